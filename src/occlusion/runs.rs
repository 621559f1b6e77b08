//! 8-connected component labelling of a 0/1 byte image by horizontal runs: one scan extracts
//! the runs of every row, a union-find over runs joins the runs of consecutive rows that touch
//! (8-adjacency), and the runs are then grouped by component. Components come in the row-major
//! order of their first pixel (the seed order of a row-major flood-fill scan), and each
//! component's runs in row-major order. Work and memory scale with the number of runs, not
//! pixels: the object sets labelled here are a few large blobs (tens of thousands of pixels in
//! a few hundred runs), where a per-pixel flood fill writes a 4-byte label and a 4-byte list
//! entry for every pixel. Reference: the flood fill `components::oracles::flood_scalar`
//! (agreement tests in components/tests.rs).

use super::components::{position_nonzero_u8, position_zero_u8};

/// One horizontal run of set pixels in image coordinates: row `y`, columns `x0..x1`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Run {
    pub y: u32,
    pub x0: u32,
    /// One past the last column.
    pub x1: u32,
}

impl Run {
    /// Pixels of the run.
    #[inline]
    pub fn len(&self) -> usize {
        (self.x1 - self.x0) as usize
    }

    /// Row-major pixel indices of the run in an image `width` wide.
    #[inline]
    pub fn pixels(&self, width: usize) -> std::ops::Range<usize> {
        let start = self.y as usize * width;
        start + self.x0 as usize..start + self.x1 as usize
    }
}

/// Run-based labelling with preallocated buffers (reused from frame to frame).
#[derive(Debug, Clone)]
pub(crate) struct RunLabelling {
    /// Every run, row-major.
    runs: Vec<Run>,
    /// Union-find parent per run; after labelling, the component of each run.
    parent: Vec<u32>,
    /// Runs grouped by component (component k: `grouped[offsets[k]..offsets[k + 1]]`).
    grouped: Vec<Run>,
    offsets: Vec<u32>,
    /// Pixels per component.
    pixels: Vec<u32>,
}

/// Root of run `i` with path halving.
#[inline]
fn find(parent: &mut [u32], mut i: u32) -> u32 {
    while parent[i as usize] != i {
        let grandparent = parent[parent[i as usize] as usize];
        parent[i as usize] = grandparent;
        i = grandparent;
    }
    i
}

/// Joins the sets of runs `a` and `b`; the smaller index stays root, so every root is the first
/// run of its component in row-major order.
#[inline]
fn union(parent: &mut [u32], a: u32, b: u32) {
    let (ra, rb) = (find(parent, a), find(parent, b));
    if ra < rb {
        parent[rb as usize] = ra;
    } else if rb < ra {
        parent[ra as usize] = rb;
    }
}

impl RunLabelling {
    /// Buffers for images of up to `width` × `height` pixels (the worst case, every other pixel
    /// set, is ⌈width / 2⌉ runs per row), so labelling never allocates.
    pub fn new(width: usize, height: usize) -> Self {
        let max_runs = width.div_ceil(2) * height;
        Self {
            runs: Vec::with_capacity(max_runs),
            parent: Vec::with_capacity(max_runs),
            grouped: Vec::with_capacity(max_runs),
            offsets: Vec::with_capacity(max_runs + 1),
            pixels: Vec::with_capacity(max_runs),
        }
    }

    /// Labels the set pixels (non-zero bytes) of the `width` × `height` window of `set` whose
    /// row r starts at `set[r * stride]`; the window's pixel (c, r) is image pixel
    /// (`origin.0` + c, `origin.1` + r). Returns the number of components.
    pub fn label(
        &mut self,
        set: &[u8],
        stride: usize,
        width: usize,
        height: usize,
        origin: (usize, usize),
    ) -> usize {
        self.runs.clear();
        self.parent.clear();
        let mut previous_row = 0..0;
        for r in 0..height {
            let row = &set[r * stride..r * stride + width];
            let row_first = self.runs.len();
            let mut x = 0;
            while let Some(offset) = position_nonzero_u8(&row[x..]) {
                let start = x + offset;
                let end = start + position_zero_u8(&row[start..]).unwrap_or(width - start);
                self.runs.push(Run {
                    y: (origin.1 + r) as u32,
                    x0: (origin.0 + start) as u32,
                    x1: (origin.0 + end) as u32,
                });
                x = end;
            }
            let current_row = row_first..self.runs.len();
            self.parent
                .extend(current_row.start as u32..current_row.end as u32);
            // Runs of consecutive rows touch (8-adjacency) when their column ranges, widened by
            // one pixel, overlap; both rows are sorted, so one merge pass finds every pair.
            let (mut i, mut j) = (previous_row.start, current_row.start);
            while i < previous_row.end && j < current_row.end {
                let (above, below) = (self.runs[i], self.runs[j]);
                if above.x0 <= below.x1 && below.x0 <= above.x1 {
                    union(&mut self.parent, i as u32, j as u32);
                }
                if above.x1 < below.x1 {
                    i += 1;
                } else {
                    j += 1;
                }
            }
            previous_row = current_row;
        }
        // Component ids in the order of the components' first runs (their roots). Links only
        // point to smaller indices, so run i's parent was already given its component id,
        // which is run i's.
        let mut components = 0u32;
        for i in 0..self.runs.len() {
            let parent = self.parent[i] as usize;
            self.parent[i] = if parent == i {
                components += 1;
                components - 1
            } else {
                self.parent[parent]
            };
        }
        // Counting sort of the runs by component (stable: row-major within a component).
        let components = components as usize;
        self.pixels.clear();
        self.pixels.resize(components, 0);
        self.offsets.clear();
        self.offsets.resize(components + 1, 0);
        for (run, &k) in self.runs.iter().zip(&self.parent) {
            self.offsets[k as usize + 1] += 1;
            self.pixels[k as usize] += run.len() as u32;
        }
        for k in 0..components {
            self.offsets[k + 1] += self.offsets[k];
        }
        self.grouped.clear();
        self.grouped.resize(self.runs.len(), Run { y: 0, x0: 0, x1: 0 });
        // The offsets serve as write cursors, then are shifted back to the starts.
        for (run, &k) in self.runs.iter().zip(&self.parent) {
            let slot = &mut self.offsets[k as usize];
            self.grouped[*slot as usize] = *run;
            *slot += 1;
        }
        // Each offset now holds the next component's start: shift back by one.
        for k in (1..=components).rev() {
            self.offsets[k] = self.offsets[k - 1];
        }
        if let Some(first) = self.offsets.first_mut() {
            *first = 0;
        }
        components
    }

    /// Runs of component `k` (row-major).
    pub fn runs(&self, k: usize) -> &[Run] {
        &self.grouped[self.offsets[k] as usize..self.offsets[k + 1] as usize]
    }

    /// Pixels of component `k`.
    pub fn pixels(&self, k: usize) -> usize {
        self.pixels[k] as usize
    }
}
