//! The genetic-programming search of the thesis (chapter 3): strongly typed
//! GP over weight expressions, seeded from the bilateral filter, with a
//! codebook, tournament selection and an island model.
//!
//! The engine never sees WGSL or the GPU: it asks an [`Evaluator`] for the
//! fitness of expressions, and reports each generation to its caller, which
//! keeps checkpoints and logs. Every random choice of generation g comes from
//! a stream seeded by (seed, g), so a run resumed from the checkpoint of
//! generation g continues exactly as the uninterrupted run would.

pub mod operators;
pub mod tree;

use std::collections::{BTreeMap, HashMap};
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};

use crate::lang::{parse_expr, Expr, Feature, ScalarVar};
use crate::rng::Rng;
use operators::{crossover, mutate, Codebook, Mutation, Terminals};

/// Fitness of an invalid expression (the thesis used the largest float).
pub const WORST: f64 = 1e30;

/// Mean over training scenes of relMSE(filtered) / relMSE(noisy); lower is better.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Fitness {
    pub value: f64,
    /// Why the expression is invalid, if it is (it then has the worst fitness).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub invalid: Option<String>,
}

impl Fitness {
    pub fn valid(value: f64) -> Self {
        Fitness { value, invalid: None }
    }
    pub fn invalid(reason: impl Into<String>) -> Self {
        Fitness { value: WORST, invalid: Some(reason.into()) }
    }
}

/// Time an evaluator spent, split as the progress report shows it.
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize)]
pub struct EvalTime {
    pub compile: Duration,
    pub evaluate: Duration,
}

/// Computes fitness. Implementations compile and run kernels; the engine only sees numbers.
pub trait Evaluator {
    /// Fitness of each expression, in order.
    fn evaluate(&mut self, exprs: &[Expr]) -> anyhow::Result<Vec<Fitness>>;
    /// Time spent since the last call.
    fn take_time(&mut self) -> EvalTime;
}

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
        }
    }
}

impl Settings {
    pub fn check(&self) -> Result<(), String> {
        if self.islands == 0 || self.island_size < 2 {
            return Err("need at least one island of at least two individuals".into());
        }
        if self.tournament == 0 {
            return Err("the tournament size must be at least 1".into());
        }
        if self.mutation_weights.len() != 4
            || self.mutation_weights.iter().any(|w| w.is_nan() || *w < 0.0)
            || self.mutation_weights.iter().sum::<f64>() <= 0.0
        {
            return Err("--mutation-weights takes four non-negative weights (insert, replace, swap, delete)".into());
        }
        let shares = [self.replication, self.crossover, self.crossover_mutation, self.seed_share];
        if shares.iter().any(|s| !(0.0..=1.0).contains(s)) || self.replication + self.crossover > 1.0 {
            return Err("shares and probabilities lie in [0, 1], and replication + crossover ≤ 1".into());
        }
        if self.max_length < 3 {
            return Err("--max-length must be at least 3".into());
        }
        Ok(())
    }
}

/// An expression with its fitness.
#[derive(Clone, Debug)]
pub struct Member {
    pub expr: Expr,
    pub text: String,
    pub fitness: Fitness,
}

/// Serialised form of a member (canonical text, read back through the grammar).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct StoredMember {
    pub expr: String,
    pub fitness: Fitness,
}

/// Everything needed to continue a run after generation `generation`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct State {
    /// Generations completed (0 = the initial population has been evaluated).
    pub generation: u32,
    pub islands: Vec<Vec<StoredMember>>,
}

/// What one generation looked like.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    pub generation: u32,
    pub best: f64,
    pub median: f64,
    pub best_expr: String,
    pub invalid: usize,
    /// Distinct expressions newly evaluated this generation.
    pub evaluated: usize,
    pub compile_s: f64,
    pub evaluate_s: f64,
    pub gp_s: f64,
}

/// The search.
pub struct Engine<'e> {
    pub settings: Settings,
    pub terminals: Terminals,
    codebook: Codebook,
    seed_expr: Expr,
    memo: HashMap<String, Fitness>,
    evaluator: &'e mut dyn Evaluator,
}

/// A stream for generation `g`, independent of every other generation's.
fn generation_rng(seed: u64, generation: u32) -> Rng {
    // SplitMix64 finaliser of (seed, generation).
    let mut z = seed ^ (generation as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    Rng::seeded(z ^ (z >> 31))
}

fn median(values: &mut [f64]) -> f64 {
    values.sort_by(f64::total_cmp);
    values[values.len() / 2]
}

impl<'e> Engine<'e> {
    pub fn new(settings: Settings, terminals: Terminals, seed_expr: Expr, evaluator: &'e mut dyn Evaluator) -> Self {
        let codebook = Codebook::new(&terminals);
        Engine { settings, terminals, codebook, seed_expr, memo: HashMap::new(), evaluator }
    }

    pub fn codebook(&self) -> &Codebook {
        &self.codebook
    }

    /// Evaluate what the memo does not know yet; returns how many were evaluated.
    fn evaluate(&mut self, islands: &mut [Vec<Member>]) -> anyhow::Result<usize> {
        let mut fresh: Vec<Expr> = Vec::new();
        let mut fresh_texts = std::collections::HashSet::new();
        for m in islands.iter().flatten() {
            if !self.memo.contains_key(&m.text) && fresh_texts.insert(m.text.clone()) {
                fresh.push(m.expr.clone());
            }
        }
        if !fresh.is_empty() {
            let results = self.evaluator.evaluate(&fresh)?;
            for (e, f) in fresh.iter().zip(results) {
                self.memo.insert(e.to_string(), f);
            }
        }
        for m in islands.iter_mut().flatten() {
            m.fitness = self.memo[&m.text].clone();
        }
        Ok(fresh.len())
    }

    fn member(expr: Expr) -> Member {
        let text = expr.to_string();
        Member { expr, text, fitness: Fitness::invalid("not evaluated") }
    }

    fn pick_mutation(&self, rng: &mut Rng) -> Mutation {
        let w = &self.settings.mutation_weights;
        let mut x = rng.unit() * w.iter().sum::<f64>();
        for (k, kind) in [Mutation::Insert, Mutation::Replace, Mutation::Swap, Mutation::Delete].into_iter().enumerate()
        {
            if x < w[k] {
                return kind;
            }
            x -= w[k];
        }
        Mutation::Delete
    }

    /// A mutation of `e` within the length limit; `e` itself when none is found.
    fn mutated(&self, e: &Expr, rng: &mut Rng) -> Expr {
        for _ in 0..10 {
            let kind = self.pick_mutation(rng);
            if let Some(m) = mutate(e, kind, &self.terminals, &self.codebook, rng) {
                if m.len() <= self.settings.max_length {
                    return m;
                }
            }
        }
        e.clone()
    }

    fn tournament<'m>(&self, island: &'m [Member], rng: &mut Rng) -> &'m Member {
        let mut best = &island[rng.below(island.len())];
        for _ in 1..self.settings.tournament {
            let m = &island[rng.below(island.len())];
            if m.fitness.value < best.fitness.value {
                best = m;
            }
        }
        best
    }

    /// Generation 0: per island, `seed_share` copies of the seed, the rest mutations of it.
    pub fn initial(&mut self) -> anyhow::Result<(State, Report)> {
        let start = Instant::now();
        let mut rng = generation_rng(self.settings.seed, 0);
        let n = self.settings.island_size;
        let copies = ((n as f64 * self.settings.seed_share).round() as usize).clamp(1, n);
        let mut islands = Vec::new();
        for _ in 0..self.settings.islands {
            let mut island = Vec::with_capacity(n);
            for k in 0..n {
                let e = if k < copies { self.seed_expr.clone() } else { self.mutated(&self.seed_expr, &mut rng) };
                island.push(Self::member(e));
            }
            islands.push(island);
        }
        let gp = start.elapsed();
        let evaluated = self.evaluate(&mut islands)?;
        Ok(self.finish(0, islands, evaluated, gp))
    }

    /// One generation after `state`.
    /// A new individual, simplified first when the settings ask for it.
    fn offspring(&self, child: Expr) -> Member {
        if self.settings.simplify_offspring {
            Self::member(crate::simplify::simplify(&child))
        } else {
            Self::member(child)
        }
    }

    pub fn step(&mut self, state: &State) -> anyhow::Result<(State, Report)> {
        let start = Instant::now();
        let generation = state.generation + 1;
        let mut rng = generation_rng(self.settings.seed, generation);
        let islands = self.restore(state)?;
        let n = self.settings.island_size;
        let replicated = (n as f64 * self.settings.replication).round() as usize;
        let crossed = ((n as f64 * self.settings.crossover).round() as usize).min(n - replicated);
        let mut next = Vec::with_capacity(islands.len());
        for island in &islands {
            let mut new: Vec<Member> = Vec::with_capacity(n);
            for _ in 0..replicated {
                new.push(self.tournament(island, &mut rng).clone());
            }
            while new.len() < replicated + crossed {
                let a = self.tournament(island, &mut rng).expr.clone();
                let b = self.tournament(island, &mut rng).expr.clone();
                let (x, y) = crossover(&a, &b, &mut rng).unwrap_or((a.clone(), b.clone()));
                for (child, parent) in [(x, a), (y, b)] {
                    if new.len() == replicated + crossed {
                        break;
                    }
                    let child = if child.len() <= self.settings.max_length { child } else { parent };
                    let child = if rng.chance(self.settings.crossover_mutation) {
                        self.mutated(&child, &mut rng)
                    } else {
                        child
                    };
                    new.push(self.offspring(child));
                }
            }
            while new.len() < n {
                let parent = self.tournament(island, &mut rng).expr.clone();
                let child = self.mutated(&parent, &mut rng);
                new.push(self.offspring(child));
            }
            next.push(new);
        }
        let gp = start.elapsed();
        let evaluated = self.evaluate(&mut next)?;
        let migrate_start = Instant::now();
        if self.settings.migration_interval > 0
            && generation.is_multiple_of(self.settings.migration_interval)
            && next.len() > 1
        {
            let best: Vec<Member> = next.iter().map(|island| best_of(island).clone()).collect();
            let count = next.len();
            for (i, migrant) in best.into_iter().enumerate() {
                let target = &mut next[(i + 1) % count];
                let worst = (0..target.len())
                    .max_by(|&a, &b| target[a].fitness.value.total_cmp(&target[b].fitness.value))
                    .expect("non-empty");
                target[worst] = migrant;
            }
        }
        Ok(self.finish(generation, next, evaluated, gp + migrate_start.elapsed()))
    }

    fn finish(
        &mut self,
        generation: u32,
        islands: Vec<Vec<Member>>,
        evaluated: usize,
        gp: Duration,
    ) -> (State, Report) {
        let time = self.evaluator.take_time();
        let all: Vec<&Member> = islands.iter().flatten().collect();
        let best = all.iter().min_by(|a, b| a.fitness.value.total_cmp(&b.fitness.value)).expect("non-empty");
        let mut values: Vec<f64> = all.iter().map(|m| m.fitness.value).collect();
        let report = Report {
            generation,
            best: best.fitness.value,
            median: median(&mut values),
            best_expr: best.text.clone(),
            invalid: all.iter().filter(|m| m.fitness.invalid.is_some()).count(),
            evaluated,
            compile_s: time.compile.as_secs_f64(),
            evaluate_s: time.evaluate.as_secs_f64(),
            gp_s: gp.as_secs_f64(),
        };
        let state = State {
            generation,
            islands: islands
                .into_iter()
                .map(|island| island.into_iter().map(|m| StoredMember { expr: m.text, fitness: m.fitness }).collect())
                .collect(),
        };
        (state, report)
    }

    /// Members from a stored state; fitness values are taken as stored.
    pub fn restore(&mut self, state: &State) -> anyhow::Result<Vec<Vec<Member>>> {
        state
            .islands
            .iter()
            .map(|island| {
                island
                    .iter()
                    .map(|s| {
                        let expr =
                            parse_expr(&s.expr).map_err(|e| anyhow::anyhow!("stored expression `{}`:\n{e}", s.expr))?;
                        self.memo.entry(s.expr.clone()).or_insert_with(|| s.fitness.clone());
                        Ok(Member { expr, text: s.expr.clone(), fitness: s.fitness.clone() })
                    })
                    .collect()
            })
            .collect()
    }
}

fn best_of(island: &[Member]) -> &Member {
    island.iter().min_by(|a, b| a.fitness.value.total_cmp(&b.fitness.value)).expect("non-empty island")
}

/// The best `k` distinct expressions of every island, best first.
pub fn hall_of_fame(state: &State, k: usize) -> Vec<(usize, StoredMember)> {
    let mut out = Vec::new();
    for (i, island) in state.islands.iter().enumerate() {
        let mut members: Vec<&StoredMember> = island.iter().collect();
        members.sort_by(|a, b| a.fitness.value.total_cmp(&b.fitness.value).then_with(|| a.expr.cmp(&b.expr)));
        let mut seen = std::collections::HashSet::new();
        for m in members {
            if seen.len() == k {
                break;
            }
            if seen.insert(m.expr.clone()) {
                out.push((i, m.clone()));
            }
        }
    }
    out
}

/// How often each terminal occurs in the populations (thesis section 4.3;
/// [`crate::lang::terminal_usage`]), every terminal listed.
pub fn feature_frequencies(state: &State) -> BTreeMap<String, usize> {
    let exprs: Vec<Expr> = state.islands.iter().flatten().filter_map(|m| parse_expr(&m.expr).ok()).collect();
    let mut counts: BTreeMap<String, usize> = Feature::ALL
        .iter()
        .map(|f| f.name())
        .chain(ScalarVar::ALL.iter().map(|v| v.name()))
        .map(|n| (n.to_string(), 0))
        .collect();
    counts.extend(crate::lang::terminal_usage(&exprs));
    counts
}
