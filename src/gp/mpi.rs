//! The [`Transport`] between MPI ranks (cargo feature `mpi`, through rsmpi on
//! the system's MPI library): one rank per process, started by `mpirun`,
//! `srun` or any other MPI launcher. docs/DISTRIBUTED.md shows how to run it.
//!
//! Messages are byte vectors; each kind has its own tag, so a migrant can
//! never be taken for a gathered part whatever the ranks' timing.

use mpi::environment::Universe;
use mpi::topology::{Communicator, SimpleCommunicator};
use mpi::traits::*;
use mpi::Threading;

use super::transport::Transport;

const MIGRANT_TAG: i32 = 1;
const GATHER_TAG: i32 = 2;

/// This process's place in an MPI job.
pub struct Mpi {
    // Dropping the universe finalises MPI: it lives as long as the communicator.
    world: SimpleCommunicator,
    node_rank: usize,
    node_ranks: usize,
    _universe: Universe,
}

impl Mpi {
    /// Join the job `mpirun` started (a job of one rank when started without
    /// a launcher). Only the thread that calls this talks to MPI; the
    /// evaluator's compile threads never do, hence `Funneled`.
    pub fn init() -> anyhow::Result<Mpi> {
        let (universe, _) = mpi::initialize_with_threading(Threading::Funneled)
            .ok_or_else(|| anyhow::anyhow!("MPI is initialised already in this process"))?;
        let world = universe.world();
        let node = world.split_shared(world.rank());
        let (node_rank, node_ranks) = (node.rank() as usize, node.size() as usize);
        Ok(Mpi { world, node_rank, node_ranks, _universe: universe })
    }

    /// This rank's position among the ranks on its node: which of the node's GPUs it takes.
    pub fn node_rank(&self) -> usize {
        self.node_rank
    }

    /// How many ranks share this rank's node.
    pub fn node_ranks(&self) -> usize {
        self.node_ranks
    }

    /// End every rank of the job (after an error on this one: the others would wait for it forever).
    pub fn abort(&self, code: i32) -> ! {
        self.world.abort(code)
    }
}

impl Transport for Mpi {
    fn rank(&self) -> usize {
        self.world.rank() as usize
    }

    fn ranks(&self) -> usize {
        self.world.size() as usize
    }

    fn pass_on(&mut self, outgoing: Vec<u8>) -> anyhow::Result<Vec<u8>> {
        let (rank, ranks) = (self.world.rank(), self.world.size());
        let next = self.world.process_at_rank((rank + 1) % ranks);
        let previous = self.world.process_at_rank((rank + ranks - 1) % ranks);
        // Every rank sends before it receives: the send must not block.
        Ok(mpi::request::scope(|scope| {
            let sent = next.immediate_send_with_tag(scope, &outgoing[..], MIGRANT_TAG);
            let (incoming, _) = previous.receive_vec_with_tag::<u8>(MIGRANT_TAG);
            sent.wait();
            incoming
        }))
    }

    fn gather(&mut self, message: Vec<u8>) -> anyhow::Result<Option<Vec<Vec<u8>>>> {
        if self.world.rank() != 0 {
            self.world.process_at_rank(0).send_with_tag(&message[..], GATHER_TAG);
            return Ok(None);
        }
        let mut all = vec![message];
        for rank in 1..self.world.size() {
            let (part, _) = self.world.process_at_rank(rank).receive_vec_with_tag::<u8>(GATHER_TAG);
            all.push(part);
        }
        Ok(Some(all))
    }

    fn broadcast(&mut self, message: Vec<u8>) -> anyhow::Result<Vec<u8>> {
        let root = self.world.process_at_rank(0);
        let mut len = message.len() as u64;
        root.broadcast_into(&mut len);
        let mut buffer = if self.world.rank() == 0 { message } else { vec![0u8; len as usize] };
        root.broadcast_into(&mut buffer[..]);
        Ok(buffer)
    }

    fn barrier(&mut self) {
        self.world.barrier();
    }
}
