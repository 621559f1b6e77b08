//! A FIFO channel between two threads bounded by the bytes it holds, not by a count.
//!
//! `occmask process` hands input messages to the frame loop and output work to the writer
//! thread through these. A message-count bound does not fit: a TUM file has ~36 messages per
//! frame (100 Hz motion capture on two topics), so eight queued messages is less than one
//! frame and the reader stalls behind small pose messages before it reaches the next image;
//! a large count bound would let big images pile up. A byte bound lets many small messages
//! and a few frames' images through while keeping memory flat.

use std::sync::mpsc::{IntoIter, SyncSender};
use std::sync::{Arc, Condvar, Mutex, PoisonError};

/// Bytes in flight, shared by both ends.
#[derive(Debug)]
struct Budget {
    /// (bytes in flight, receiver dropped)
    state: Mutex<(usize, bool)>,
    freed: Condvar,
    limit: usize,
}

/// The sending end; see [`byte_queue`].
#[derive(Debug)]
pub struct ByteSender<T> {
    items: SyncSender<(T, usize)>,
    budget: Arc<Budget>,
}

/// The receiving end; see [`byte_queue`]. Dropping it unblocks and fails the sender.
#[derive(Debug)]
pub struct ByteReceiver<T> {
    items: IntoIter<(T, usize)>,
    budget: Arc<Budget>,
}

/// A queue holding at most `limit_bytes` (as the sender declares them; one item is always let
/// through, however big) and at most `max_items` items.
pub fn byte_queue<T>(limit_bytes: usize, max_items: usize) -> (ByteSender<T>, ByteReceiver<T>) {
    let (tx, rx) = std::sync::mpsc::sync_channel::<(T, usize)>(max_items.max(1));
    let budget = Arc::new(Budget {
        state: Mutex::new((0, false)),
        freed: Condvar::new(),
        limit: limit_bytes,
    });
    (
        ByteSender {
            items: tx,
            budget: Arc::clone(&budget),
        },
        ByteReceiver {
            items: rx.into_iter(),
            budget,
        },
    )
}

impl<T> ByteSender<T> {
    /// Queues `item` of `bytes` bytes, waiting while the queue is over its budget. Returns the
    /// item back when the receiver is gone.
    ///
    /// # Errors
    /// The item, when the receiver has been dropped.
    pub fn send(&self, item: T, bytes: usize) -> Result<(), T> {
        {
            let mut state = self.budget.state.lock().unwrap_or_else(PoisonError::into_inner);
            while !state.1 && state.0 > 0 && state.0.saturating_add(bytes) > self.budget.limit {
                state = self
                    .budget
                    .freed
                    .wait(state)
                    .unwrap_or_else(PoisonError::into_inner);
            }
            if state.1 {
                return Err(item);
            }
            state.0 = state.0.saturating_add(bytes);
        }
        self.items.send((item, bytes)).map_err(|e| e.0 .0)
    }
}

impl<T> Iterator for ByteReceiver<T> {
    type Item = T;

    /// The next item, waiting for it; `None` once every sender is gone and the queue is empty.
    fn next(&mut self) -> Option<T> {
        let (item, bytes) = self.items.next()?;
        let mut state = self.budget.state.lock().unwrap_or_else(PoisonError::into_inner);
        state.0 = state.0.saturating_sub(bytes);
        self.budget.freed.notify_all();
        Some(item)
    }
}

impl<T> Drop for ByteReceiver<T> {
    fn drop(&mut self) {
        let mut state = self.budget.state.lock().unwrap_or_else(PoisonError::into_inner);
        state.1 = true;
        self.budget.freed.notify_all();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};

    #[test]
    fn keeps_order_and_ends_when_the_sender_is_gone() {
        let (tx, rx) = byte_queue(10, 100);
        std::thread::scope(|s| {
            s.spawn(move || {
                for i in 0..1000u32 {
                    tx.send(i, (i % 7) as usize).unwrap();
                }
            });
            let got: Vec<u32> = rx.collect();
            assert_eq!(got, (0..1000).collect::<Vec<_>>());
        });
    }

    #[test]
    fn holds_at_most_the_budget_but_always_one_item() {
        let (tx, rx) = byte_queue::<usize>(100, 1000);
        let sent = AtomicUsize::new(0);
        std::thread::scope(|s| {
            s.spawn(|| {
                // 40-byte items: two fit in 100 bytes, the third waits.
                for i in 0..3 {
                    tx.send(i, 40).unwrap();
                    sent.fetch_add(1, Ordering::SeqCst);
                }
                // Bigger than the whole budget: still goes through once the queue is empty.
                tx.send(99, 500).unwrap();
                sent.fetch_add(1, Ordering::SeqCst);
                drop(tx);
            });
            let mut rx = rx;
            let start = std::time::Instant::now();
            while sent.load(Ordering::SeqCst) < 2 && start.elapsed().as_secs() < 10 {
                std::thread::sleep(std::time::Duration::from_millis(1));
            }
            // Give the sender time to (wrongly) queue the third item.
            std::thread::sleep(std::time::Duration::from_millis(100));
            assert_eq!(
                sent.load(Ordering::SeqCst),
                2,
                "the third item must wait for room"
            );
            assert_eq!(rx.next(), Some(0));
            assert_eq!(rx.next(), Some(1));
            assert_eq!(rx.next(), Some(2));
            assert_eq!(rx.next(), Some(99));
            assert_eq!(rx.next(), None);
        });
    }

    #[test]
    fn a_dropped_receiver_unblocks_and_fails_the_sender() {
        let (tx, rx) = byte_queue::<u8>(10, 100);
        std::thread::scope(|s| {
            let sender = s.spawn(move || {
                tx.send(1, 10).unwrap();
                // Over budget: blocks until the receiver is dropped, then fails.
                tx.send(2, 10)
            });
            std::thread::sleep(std::time::Duration::from_millis(50));
            drop(rx);
            assert_eq!(sender.join().unwrap(), Err(2));
        });
    }
}
