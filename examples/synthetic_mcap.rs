//! Writes synthetic RGB-D scenarios (src/synthetic.rs: exact ground-truth masks and poses) as
//! MCAP files in `occmask convert`'s layout, so `occmask process` + `occmask eval` can be scored
//! on sequences with moving objects and exact ground-truth masks (no real sequence here has them).
//!
//! usage: cargo run --release --example synthetic_mcap -- OUT_DIR [SCENARIO...]
//! (default: every scenario; files are OUT_DIR/<scenario>.mcap, 640×480)

use std::io::BufWriter;
use std::ops::ControlFlow;

use occmask::convert::write_synthetic_sequence;
use occmask::mcap_io::McapWriteOptions;
use occmask::synthetic::{Scenario, SequenceConfig, SyntheticSequence};

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let out_dir = std::path::PathBuf::from(
        args.first()
            .ok_or_else(|| anyhow::anyhow!("usage: OUT_DIR [SCENARIO...]"))?,
    );
    std::fs::create_dir_all(&out_dir)?;
    let wanted: Vec<&String> = args[1..].iter().collect();
    for scenario in Scenario::ALL {
        if !wanted.is_empty() && !wanted.iter().any(|w| w.as_str() == scenario.name()) {
            continue;
        }
        let sequence = SyntheticSequence::new(scenario, SequenceConfig::default());
        let path = out_dir.join(format!("{}.mcap", scenario.name()));
        let file = BufWriter::new(std::fs::File::create(&path)?);
        write_synthetic_sequence(&sequence, file, &McapWriteOptions::default(), &mut |_| {
            ControlFlow::Continue(())
        })?;
        println!("{} ({} frames)", path.display(), sequence.len());
    }
    Ok(())
}
