//! Every parameter of the search, with the thesis's defaults, and their check.

use serde::{Deserialize, Serialize};

use super::Objectives;

/// Every parameter of the search, with the thesis's defaults.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Settings {
    /// Number of islands.
    pub islands: usize,
    /// Individuals per island.
    pub island_size: usize,
    /// Generations to run (the stopping rule).
    pub generations: u32,
    /// Longest expression allowed, in nodes.
    pub max_length: usize,
    /// Tournament size.
    pub tournament: usize,
    /// Share of each new generation copied unchanged.
    pub replication: f64,
    /// Share made by crossover; the rest is made by mutation.
    pub crossover: f64,
    /// Probability that a crossover child is also mutated.
    pub crossover_mutation: f64,
    /// Relative weights of the mutations insert, replace, swap, delete.
    pub mutation_weights: Vec<f64>,
    /// Migrate the best of island i to island (i+1) mod n every this many generations.
    pub migration_interval: u32,
    /// Share of each initial island that is the seed expression itself.
    pub seed_share: f64,
    /// Hall of fame: the best this many of every island.
    pub hall_of_fame: usize,
    /// Random seed.
    pub seed: u64,
    /// Replace every new individual by its simplified form (`crate::simplify`,
    /// the same weights) before it is evaluated.
    #[serde(default)]
    pub simplify_offspring: bool,
    /// What the search minimises (runs made before there was a choice: error).
    #[serde(default)]
    pub objectives: Objectives,
    /// With two objectives: how many islands (the first) still minimise
    /// error alone at the largest radius, as the thesis's search does, so
    /// that the front's accurate end evolves as fast as a single-objective run's.
    #[serde(default)]
    pub error_islands: usize,
    /// The best this many of each island pass to the next generation
    /// unchanged, before the replication share is drawn by tournament (and
    /// count towards it): the best filter found is never lost. 0 is the
    /// thesis's search (runs made before it existed: 0).
    #[serde(default)]
    pub elites: usize,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            islands: 4,
            island_size: 100,
            generations: 200,
            max_length: 75,
            tournament: 8,
            replication: 0.1,
            crossover: 0.45,
            crossover_mutation: 0.85,
            mutation_weights: vec![0.3, 0.3, 0.3, 0.1],
            migration_interval: 5,
            seed_share: 0.1,
            hall_of_fame: 10,
            seed: 0,
            simplify_offspring: false,
            objectives: Objectives::Error,
            error_islands: 0,
            elites: 0,
        }
    }
}

impl Settings {
    pub fn check(&self) -> Result<(), String> {
        if self.islands == 0 || self.island_size < 2 {
            return Err("need at least one island of at least two individuals".into());
        }
        if self.elites > self.island_size {
            return Err(format!("elites: {} is more than an island's {} individuals", self.elites, self.island_size));
        }
        if self.tournament == 0 {
            return Err("the tournament size must be at least 1".into());
        }
        if self.mutation_weights.len() != 4
            || self.mutation_weights.iter().any(|w| w.is_nan() || *w < 0.0)
            || self.mutation_weights.iter().sum::<f64>() <= 0.0
        {
            return Err(
                "mutation weights: four non-negative weights (insert, replace, swap, delete), not all zero".into()
            );
        }
        let shares = [self.replication, self.crossover, self.crossover_mutation, self.seed_share];
        if shares.iter().any(|s| !(0.0..=1.0).contains(s)) || self.replication + self.crossover > 1.0 {
            return Err("shares and probabilities lie in [0, 1], and replication + crossover ≤ 1".into());
        }
        if self.error_islands > self.islands {
            return Err(format!("error islands: {} is more than the {} islands", self.error_islands, self.islands));
        }
        if self.max_length < 3 {
            return Err("max length: at least 3 nodes".into());
        }
        Ok(())
    }
}
