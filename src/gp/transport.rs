//! How islands held by different processes talk: the thesis's ring migration
//! and the root's view of the whole population, as byte messages.
//!
//! The engine serialises what it sends; a transport only moves bytes, so the
//! MPI one ([`super::mpi`], cargo feature `mpi`) knows nothing of GP. Every
//! process holds a contiguous block of the run's islands ([`share`]), so the
//! ring `i → i + 1 mod n` crosses processes only between the last island of
//! one block and the first of the next: one point-to-point message each way.

use std::ops::Range;

/// Messages between the processes of one run. Every method is collective:
/// each process calls it at the same point of the run, in the same order.
pub trait Transport {
    /// This process's position and the number of processes.
    fn rank(&self) -> usize;
    fn ranks(&self) -> usize;
    /// Send `outgoing` to the next process of the ring; returns what the
    /// previous one sent (with one process: `outgoing` itself).
    fn pass_on(&mut self, outgoing: Vec<u8>) -> anyhow::Result<Vec<u8>>;
    /// Every process's message, in rank order, at rank 0; `None` elsewhere.
    fn gather(&mut self, message: Vec<u8>) -> anyhow::Result<Option<Vec<Vec<u8>>>>;
    /// Rank 0's message, at every process (others pass anything; it is ignored).
    fn broadcast(&mut self, message: Vec<u8>) -> anyhow::Result<Vec<u8>>;
    /// Wait until every process has arrived here.
    fn barrier(&mut self);

    fn is_root(&self) -> bool {
        self.rank() == 0
    }
}

/// One process holding every island: what `filterjit evolve` does without MPI.
#[derive(Clone, Copy, Debug, Default)]
pub struct InProcess;

impl Transport for InProcess {
    fn rank(&self) -> usize {
        0
    }
    fn ranks(&self) -> usize {
        1
    }
    fn pass_on(&mut self, outgoing: Vec<u8>) -> anyhow::Result<Vec<u8>> {
        Ok(outgoing)
    }
    fn gather(&mut self, message: Vec<u8>) -> anyhow::Result<Option<Vec<Vec<u8>>>> {
        Ok(Some(vec![message]))
    }
    fn broadcast(&mut self, message: Vec<u8>) -> anyhow::Result<Vec<u8>> {
        Ok(message)
    }
    fn barrier(&mut self) {}
}

impl<T: Transport + ?Sized> Transport for &mut T {
    fn rank(&self) -> usize {
        (**self).rank()
    }
    fn ranks(&self) -> usize {
        (**self).ranks()
    }
    fn pass_on(&mut self, outgoing: Vec<u8>) -> anyhow::Result<Vec<u8>> {
        (**self).pass_on(outgoing)
    }
    fn gather(&mut self, message: Vec<u8>) -> anyhow::Result<Option<Vec<Vec<u8>>>> {
        (**self).gather(message)
    }
    fn broadcast(&mut self, message: Vec<u8>) -> anyhow::Result<Vec<u8>> {
        (**self).broadcast(message)
    }
    fn barrier(&mut self) {
        (**self).barrier()
    }
}

/// The islands process `rank` of `ranks` holds, of `islands`: contiguous
/// blocks whose sizes differ by at most one, in rank order.
pub fn share(islands: usize, rank: usize, ranks: usize) -> Range<usize> {
    let start = |r: usize| r * islands / ranks;
    start(rank)..start(rank + 1)
}

#[cfg(test)]
mod tests {
    use super::share;

    #[test]
    fn shares_cover_the_islands_once_in_order() {
        for islands in 1..12 {
            for ranks in 1..=islands {
                let blocks: Vec<_> = (0..ranks).map(|r| share(islands, r, ranks)).collect();
                assert_eq!(blocks[0].start, 0);
                assert_eq!(blocks[ranks - 1].end, islands);
                for w in blocks.windows(2) {
                    assert_eq!(w[0].end, w[1].start);
                }
                let sizes: Vec<usize> = blocks.iter().map(|b| b.len()).collect();
                assert!(sizes.iter().all(|&s| s >= 1));
                assert!(sizes.iter().max().unwrap() - sizes.iter().min().unwrap() <= 1);
            }
        }
    }
}

/// Processes played by threads, for testing what the engine does across
/// processes without an MPI library: channels in a ring, to the root and from it.
#[cfg(test)]
pub(crate) mod threads {
    use std::sync::mpsc::{channel, Receiver, Sender};
    use std::sync::{Arc, Barrier};

    use super::Transport;

    pub struct Threads {
        rank: usize,
        ranks: usize,
        next: Sender<Vec<u8>>,
        previous: Receiver<Vec<u8>>,
        to_root: Sender<Vec<u8>>,
        /// At the root, one channel per rank: a fast rank's next message must not pass a slow one's.
        at_root: Vec<Receiver<Vec<u8>>>,
        from_root: Vec<Sender<Vec<u8>>>,
        broadcast: Receiver<Vec<u8>>,
        barrier: Arc<Barrier>,
    }

    /// One transport per rank of a job of `ranks`.
    pub fn job(ranks: usize) -> Vec<Threads> {
        let (ring_tx, ring_rx): (Vec<_>, Vec<_>) = (0..ranks).map(|_| channel()).unzip();
        let (cast_tx, cast_rx): (Vec<_>, Vec<_>) = (0..ranks).map(|_| channel()).unzip();
        let (to_root, at_root): (Vec<_>, Vec<_>) = (0..ranks).map(|_| channel()).unzip();
        let barrier = Arc::new(Barrier::new(ranks));
        let mut at_root = Some(at_root);
        ring_rx
            .into_iter()
            .zip(cast_rx)
            .enumerate()
            .map(|(rank, (previous, broadcast))| Threads {
                rank,
                ranks,
                next: ring_tx[(rank + 1) % ranks].clone(),
                previous,
                to_root: to_root[rank].clone(),
                at_root: at_root.take().unwrap_or_default(),
                from_root: if rank == 0 { cast_tx.clone() } else { Vec::new() },
                broadcast,
                barrier: barrier.clone(),
            })
            .collect()
    }

    impl Transport for Threads {
        fn rank(&self) -> usize {
            self.rank
        }
        fn ranks(&self) -> usize {
            self.ranks
        }
        fn pass_on(&mut self, outgoing: Vec<u8>) -> anyhow::Result<Vec<u8>> {
            self.next.send(outgoing)?;
            Ok(self.previous.recv()?)
        }
        fn gather(&mut self, message: Vec<u8>) -> anyhow::Result<Option<Vec<Vec<u8>>>> {
            self.to_root.send(message)?;
            if self.rank != 0 {
                return Ok(None);
            }
            Ok(Some(self.at_root.iter().map(|r| r.recv()).collect::<Result<_, _>>()?))
        }
        fn broadcast(&mut self, message: Vec<u8>) -> anyhow::Result<Vec<u8>> {
            for to in &self.from_root {
                to.send(message.clone())?;
            }
            Ok(self.broadcast.recv()?)
        }
        fn barrier(&mut self) {
            self.barrier.wait();
        }
    }
}
