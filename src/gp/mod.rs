//! The genetic-programming search of the thesis (chapter 3): strongly typed
//! GP over weight expressions, seeded from the bilateral filter, with a
//! codebook, tournament selection and an island model.
//!
//! The engine never sees WGSL or the GPU: it asks an [`Evaluator`] for the
//! fitness of expressions, and reports each generation to its caller, which
//! keeps checkpoints and logs. Every random choice of island i in generation
//! g comes from a stream seeded by (seed, g, i), so a run resumed from the
//! checkpoint of generation g continues exactly as the uninterrupted run
//! would, and islands spread over processes ([`transport`]) evolve exactly as
//! they do in one.

mod fitness;
#[cfg(feature = "mpi")]
pub mod mpi;
pub mod operators;
pub mod pareto;
mod settings;
pub mod transport;
pub mod tree;

use std::collections::{BTreeMap, HashMap};
use std::ops::Range;
use std::time::{Duration, Instant};

use anyhow::Context;
use serde::{Deserialize, Serialize};

use crate::lang::{parse_expr, Expr, Feature, ScalarVar};
use crate::rng::Rng;
use operators::{crossover, mutate, Codebook, Mutation, Terminals};
use transport::{InProcess, Transport};

pub use fitness::{Candidate, EvalTime, Evaluator, Fitness, Objectives, NO_CHOICE, WORST};
pub use settings::Settings;

/// An expression with its fitness.
#[derive(Clone, Debug)]
pub struct Member {
    pub expr: Expr,
    pub text: String,
    /// The window radius, where the search evolves it ([`Engine::set_radii`]).
    pub radius: Option<u32>,
    pub fitness: Fitness,
}

impl Member {
    /// What tells two individuals apart: the expression, and the radius where there is one.
    fn key(&self) -> String {
        member_key(&self.text, self.radius)
    }

    fn stored(&self) -> StoredMember {
        StoredMember { expr: self.text.clone(), fitness: self.fitness.clone(), radius: self.radius }
    }
}

fn member_key(text: &str, radius: Option<u32>) -> String {
    match radius {
        None => text.to_string(),
        Some(r) => format!("r{r}:{text}"),
    }
}

/// Serialised form of a member (canonical text, read back through the grammar).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct StoredMember {
    pub expr: String,
    pub fitness: Fitness,
    /// Its own window radius (runs that evolve the radius); absent: the run's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radius: Option<u32>,
}

impl StoredMember {
    pub fn key(&self) -> String {
        member_key(&self.expr, self.radius)
    }
}

/// Probability that a new individual's radius moves one step (runs that evolve it).
pub const RADIUS_MUTATION: f64 = 0.2;

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
    /// Compile, evaluate and GP times are the slowest process's (they work in parallel).
    pub compile_s: f64,
    pub evaluate_s: f64,
    pub gp_s: f64,
    /// Time the root spent on migration and on gathering the islands
    /// (waiting for the slowest process included).
    #[serde(default)]
    pub transfer_s: f64,
    /// The whole generation at the root, from breeding to the gathered population.
    #[serde(default)]
    pub seconds: f64,
    /// Processes holding the islands.
    #[serde(default)]
    pub ranks: usize,
    /// Distinct members on the whole population's non-dominated front (multi-objective runs).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub front: Option<usize>,
}

/// What one process sends the root after each generation: its islands and its work.
#[derive(Serialize, Deserialize)]
struct Part {
    first: usize,
    islands: Vec<Vec<StoredMember>>,
    evaluated: usize,
    compile_s: f64,
    evaluate_s: f64,
    gp_s: f64,
}

/// The search.
pub struct Engine<'e> {
    pub settings: Settings,
    pub terminals: Terminals,
    codebook: Codebook,
    seed_expr: Expr,
    memo: HashMap<String, Fitness>,
    evaluator: &'e mut dyn Evaluator,
    transport: Box<dyn Transport + 'e>,
    /// The islands this process holds, of `settings.islands`.
    held: Range<usize>,
    /// Their members after generation `generation`, once there is one.
    current: Option<(u32, Vec<Vec<Member>>)>,
    /// The radii individuals may have, when the radius is a gene.
    radii: Option<std::ops::RangeInclusive<u32>>,
}

/// SplitMix64's finaliser: a well-mixed 64-bit value from any.
fn mix(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// The stream of island `island` in generation `generation`, independent of every other's.
fn island_rng(seed: u64, generation: u32, island: usize) -> Rng {
    let z = mix(seed ^ (generation as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15));
    Rng::seeded(mix(z ^ (island as u64 + 1).wrapping_mul(0xd1b5_4a32_d192_ed03)))
}

fn median(values: &mut [f64]) -> f64 {
    values.sort_by(f64::total_cmp);
    values[values.len() / 2]
}

impl<'e> Engine<'e> {
    /// A search whose islands all live in this process.
    pub fn new(
        settings: Settings,
        terminals: Terminals,
        seed_expr: Expr,
        evaluator: &'e mut dyn Evaluator,
    ) -> anyhow::Result<Self> {
        Self::with_transport(settings, terminals, seed_expr, evaluator, Box::new(InProcess))
    }

    /// A search whose islands are shared among the processes `transport`
    /// reaches; this one evolves its share ([`transport::share`]).
    pub fn with_transport(
        settings: Settings,
        terminals: Terminals,
        seed_expr: Expr,
        evaluator: &'e mut dyn Evaluator,
        transport: Box<dyn Transport + 'e>,
    ) -> anyhow::Result<Self> {
        let ranks = transport.ranks();
        if settings.islands < ranks {
            anyhow::bail!(
                "{} islands cannot be shared among {ranks} processes: give each at least one",
                settings.islands
            );
        }
        if seed_expr.len() > settings.max_length {
            // Every offspring of it would be too long and fall back to its
            // parent: the population would stay copies of the seed.
            anyhow::bail!(
                "the seed expression has {} nodes, more than --max-length {}: none of its offspring would fit, \
                 so the search could not move from it; give --max-length {} or more",
                seed_expr.len(),
                settings.max_length,
                seed_expr.len()
            );
        }
        let held = transport::share(settings.islands, transport.rank(), ranks);
        let codebook = Codebook::new(&terminals);
        Ok(Engine {
            settings,
            terminals,
            codebook,
            seed_expr,
            memo: HashMap::new(),
            evaluator,
            transport,
            held,
            current: None,
            radii: None,
        })
    }

    /// Evolve each individual's window radius too, within `radii` (the seed
    /// copies start at its end). Set before the first generation.
    pub fn set_radii(&mut self, radii: std::ops::RangeInclusive<u32>) {
        self.radii = Some(radii);
    }

    /// A radius one step from `radius` with probability [`RADIUS_MUTATION`], within the range.
    fn mutated_radius(&self, island: usize, radius: Option<u32>, rng: &mut Rng) -> Option<u32> {
        let (Some(radii), Some(r)) = (&self.radii, radius) else { return radius };
        if self.objectives_of(island) == Objectives::Error {
            return radius;
        }
        if !rng.chance(RADIUS_MUTATION) {
            return radius;
        }
        let step = if rng.chance(0.5) { r.saturating_sub(1) } else { r + 1 };
        Some(step.clamp(*radii.start(), *radii.end()))
    }

    /// The islands this process evolves.
    pub fn held(&self) -> Range<usize> {
        self.held.clone()
    }

    /// The last generation this process completed, if any.
    pub fn generation(&self) -> Option<u32> {
        self.current.as_ref().map(|(g, _)| *g)
    }

    pub fn codebook(&self) -> &Codebook {
        &self.codebook
    }

    /// Evaluate what the memo does not know yet; returns how many were evaluated.
    fn evaluate(&mut self, islands: &mut [Vec<Member>]) -> anyhow::Result<usize> {
        let mut fresh: Vec<Candidate> = Vec::new();
        let mut fresh_keys = Vec::new();
        let mut seen = std::collections::HashSet::new();
        for m in islands.iter().flatten() {
            let key = m.key();
            if !self.memo.contains_key(&key) && seen.insert(key.clone()) {
                fresh.push(Candidate { expr: m.expr.clone(), radius: m.radius });
                fresh_keys.push(key);
            }
        }
        if !fresh.is_empty() {
            let results = self.evaluator.evaluate(&fresh)?;
            for (key, f) in fresh_keys.into_iter().zip(results) {
                self.memo.insert(key, f);
            }
        }
        for m in islands.iter_mut().flatten() {
            m.fitness = self.memo[&m.key()].clone();
        }
        Ok(fresh.len())
    }

    fn member(expr: Expr, radius: Option<u32>) -> Member {
        let text = expr.to_string();
        Member { expr, text, radius, fitness: Fitness::invalid("not evaluated") }
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

    /// Whether an offspring is within the length limit and the depth any
    /// expression may have (the parser's, so that it can be stored and read back).
    fn fits(&self, e: &Expr) -> bool {
        e.len() <= self.settings.max_length && e.depth() <= crate::lang::MAX_DEPTH
    }

    /// A mutation of `e` within the length limit; `e` itself when none is found.
    fn mutated(&self, e: &Expr, rng: &mut Rng) -> Expr {
        for _ in 0..10 {
            let kind = self.pick_mutation(rng);
            if let Some(m) = mutate(e, kind, &self.terminals, &self.codebook, rng) {
                if self.fits(&m) {
                    return m;
                }
            }
        }
        e.clone()
    }

    /// What island `island` minimises.
    fn objectives_of(&self, island: usize) -> Objectives {
        match self.settings.objectives {
            Objectives::ErrorCost if island < self.settings.error_islands => Objectives::Error,
            objectives => objectives,
        }
    }

    /// Each member's standing in island `index`, lower is better: its fitness,
    /// or with two objectives its place by front and crowding.
    fn standing(&self, index: usize, island: &[Member]) -> Vec<f64> {
        match self.objectives_of(index) {
            Objectives::Error => island.iter().map(|m| m.fitness.value).collect(),
            Objectives::ErrorCost => {
                let points: Vec<Vec<f64>> = island.iter().map(|m| m.fitness.objectives()).collect();
                pareto::places(&points).into_iter().map(|p| p as f64).collect()
            }
        }
    }

    fn tournament<'m>(&self, island: &'m [Member], standing: &[f64], rng: &mut Rng) -> &'m Member {
        let mut best = rng.below(island.len());
        for _ in 1..self.settings.tournament {
            let k = rng.below(island.len());
            if standing[k] < standing[best] {
                best = k;
            }
        }
        &island[best]
    }

    /// NSGA-II's survivors: the best `island_size` of parents and offspring
    /// together, by front and crowding, each expression once where there are enough.
    fn survivors(&self, parents: &[Member], offspring: Vec<Member>) -> Vec<Member> {
        let pool: Vec<Member> = parents.iter().cloned().chain(offspring).collect();
        let mut seen = std::collections::HashSet::new();
        // One individual per point: clones and equally good twins (say, many
        // weights that filter nothing) would otherwise crowd out the front.
        let (distinct, repeats): (Vec<usize>, Vec<usize>) =
            (0..pool.len()).partition(|&k| seen.insert(pool[k].fitness.point_key()));
        let points: Vec<Vec<f64>> = distinct.iter().map(|&k| pool[k].fitness.objectives()).collect();
        let chosen = pareto::order(&points).into_iter().map(|k| distinct[k]).chain(repeats);
        chosen.take(self.settings.island_size).map(|k| pool[k].clone()).collect()
    }

    /// Generation 0: per island, `seed_share` copies of the seed, the rest
    /// mutations of it. The whole population and its report come back at the
    /// root process (always, in one process); `None` at the others.
    pub fn initial(&mut self) -> anyhow::Result<Option<(State, Report)>> {
        let start = Instant::now();
        let n = self.settings.island_size;
        let copies = ((n as f64 * self.settings.seed_share).round() as usize).clamp(1, n);
        let mut islands = Vec::new();
        for i in self.held() {
            let mut rng = island_rng(self.settings.seed, 0, i);
            let mut island = Vec::with_capacity(n);
            for k in 0..n {
                let e = if k < copies { self.seed_expr.clone() } else { self.mutated(&self.seed_expr, &mut rng) };
                // Where the radius is a gene, the seed keeps the largest and mutants draw theirs.
                let keep = k < copies || self.objectives_of(i) == Objectives::Error;
                let radius = self.radii.as_ref().map(|radii| match keep {
                    true => *radii.end(),
                    false => radii.start() + rng.below((radii.end() - radii.start() + 1) as usize) as u32,
                });
                island.push(Self::member(e, radius));
            }
            islands.push(island);
        }
        let gp = start.elapsed();
        let evaluated = self.evaluate(&mut islands)?;
        self.finish(0, islands, evaluated, gp, Duration::ZERO, start)
    }

    /// Continue from `state` (a checkpoint of the whole population): this process takes its islands.
    pub fn resume(&mut self, state: &State) -> anyhow::Result<()> {
        if state.islands.len() != self.settings.islands {
            anyhow::bail!(
                "the state holds {} islands; the settings ask for {}",
                state.islands.len(),
                self.settings.islands
            );
        }
        let islands = self.restore(&state.islands[self.held()])?;
        self.current = Some((state.generation, islands));
        Ok(())
    }

    /// One generation after `state`.
    /// A new individual, simplified first when the settings ask for it.
    fn offspring(&self, island: usize, child: Expr, radius: Option<u32>, rng: &mut Rng) -> Member {
        let radius = self.mutated_radius(island, radius, rng);
        if self.settings.simplify_offspring {
            Self::member(crate::simplify::simplify(&child), radius)
        } else {
            Self::member(child, radius)
        }
    }

    /// The generation after the last one (`initial` or `resume` first);
    /// returns like [`Engine::initial`].
    pub fn step(&mut self) -> anyhow::Result<Option<(State, Report)>> {
        let start = Instant::now();
        let (done, islands) = self.current.take().ok_or_else(|| anyhow::anyhow!("no generation to step from"))?;
        let generation = done + 1;
        let n = self.settings.island_size;
        let replicated = (n as f64 * self.settings.replication).round() as usize;
        let crossed = ((n as f64 * self.settings.crossover).round() as usize).min(n - replicated);
        let mut next = Vec::with_capacity(islands.len());
        for (i, island) in self.held().zip(&islands) {
            let mut rng = island_rng(self.settings.seed, generation, i);
            let standing = self.standing(i, island);
            let standing = &standing;
            let mut new: Vec<Member> = Vec::with_capacity(n);
            let mut ranked: Vec<usize> = (0..island.len()).collect();
            ranked.sort_by(|&a, &b| standing[a].total_cmp(&standing[b]));
            new.extend(ranked.iter().take(self.settings.elites.min(n)).map(|&k| island[k].clone()));
            while new.len() < replicated {
                new.push(self.tournament(island, standing, &mut rng).clone());
            }
            while new.len() < replicated + crossed {
                let pa = self.tournament(island, standing, &mut rng);
                let pb = self.tournament(island, standing, &mut rng);
                let (a, b, ra, rb) = (pa.expr.clone(), pb.expr.clone(), pa.radius, pb.radius);
                let (x, y) = crossover(&a, &b, &mut rng).unwrap_or((a.clone(), b.clone()));
                for (child, parent, radius) in [(x, a, ra), (y, b, rb)] {
                    if new.len() == replicated + crossed {
                        break;
                    }
                    let child = if self.fits(&child) { child } else { parent };
                    let child = if rng.chance(self.settings.crossover_mutation) {
                        self.mutated(&child, &mut rng)
                    } else {
                        child
                    };
                    new.push(self.offspring(i, child, radius, &mut rng));
                }
            }
            while new.len() < n {
                let parent = self.tournament(island, standing, &mut rng);
                let (parent, radius) = (parent.expr.clone(), parent.radius);
                let child = self.mutated(&parent, &mut rng);
                new.push(self.offspring(i, child, radius, &mut rng));
            }
            next.push(new);
        }
        let gp = start.elapsed();
        let evaluated = self.evaluate(&mut next)?;
        next = self
            .held()
            .zip(&islands)
            .zip(next)
            .map(|((i, parents), offspring)| match self.objectives_of(i) {
                Objectives::ErrorCost => self.survivors(parents, offspring),
                Objectives::Error => offspring,
            })
            .collect();
        let migrate_start = Instant::now();
        if self.settings.migration_interval > 0
            && generation.is_multiple_of(self.settings.migration_interval)
            && self.settings.islands > 1
        {
            self.migrate(&mut next)?;
        }
        self.finish(generation, next, evaluated, gp, migrate_start.elapsed(), start)
    }

    /// The thesis's ring: the best of island i replaces the worst of island
    /// i + 1 (mod n), every best chosen before any is replaced. The last held
    /// island's best goes to the next process; the first receives the previous one's.
    fn migrate(&mut self, islands: &mut [Vec<Member>]) -> anyhow::Result<()> {
        let mut arriving: Vec<Member> = islands.iter().map(|island| best_of(island).clone()).collect();
        let outgoing = arriving.pop().expect("a process holds at least one island");
        let sent = outgoing.stored();
        let received: StoredMember = serde_json::from_slice(&self.transport.pass_on(serde_json::to_vec(&sent)?)?)?;
        let expr = parse_expr(&received.expr).with_context(|| format!("migrant `{}`", received.expr))?;
        arriving.insert(0, Member { expr, text: received.expr, radius: received.radius, fitness: received.fitness });
        for ((i, target), migrant) in self.held().zip(islands.iter_mut()).zip(arriving) {
            let standing = self.standing(i, target);
            let worst = (0..target.len()).max_by(|&a, &b| standing[a].total_cmp(&standing[b])).expect("non-empty");
            target[worst] = migrant;
        }
        Ok(())
    }

    /// Keep this process's islands for the next step and send them to the
    /// root, which assembles the whole population and its report.
    fn finish(
        &mut self,
        generation: u32,
        islands: Vec<Vec<Member>>,
        evaluated: usize,
        gp: Duration,
        migration: Duration,
        start: Instant,
    ) -> anyhow::Result<Option<(State, Report)>> {
        let time = self.evaluator.take_time();
        let gather_start = Instant::now();
        let part = Part {
            first: self.held.start,
            islands: islands.iter().map(|island| island.iter().map(Member::stored).collect()).collect(),
            evaluated,
            compile_s: time.compile.as_secs_f64(),
            evaluate_s: time.evaluate.as_secs_f64(),
            gp_s: gp.as_secs_f64(),
        };
        self.current = Some((generation, islands));
        let Some(messages) = self.transport.gather(serde_json::to_vec(&part)?)? else { return Ok(None) };
        let parts: Vec<Part> = messages.iter().map(|m| serde_json::from_slice(m)).collect::<Result<_, _>>()?;
        let ranks = parts.len();
        let mut islands = Vec::with_capacity(self.settings.islands);
        let (mut evaluated, mut compile_s, mut evaluate_s, mut gp_s) = (0, 0f64, 0f64, 0f64);
        for part in parts {
            if part.first != islands.len() {
                anyhow::bail!("a process sent islands from {}, expected {}", part.first, islands.len());
            }
            islands.extend(part.islands);
            evaluated += part.evaluated;
            compile_s = compile_s.max(part.compile_s);
            evaluate_s = evaluate_s.max(part.evaluate_s);
            gp_s = gp_s.max(part.gp_s);
        }
        let state = State { generation, islands };
        let all: Vec<&StoredMember> = state.islands.iter().flatten().collect();
        let best = all.iter().min_by(|a, b| a.fitness.value.total_cmp(&b.fitness.value)).expect("non-empty");
        let mut values: Vec<f64> = all.iter().map(|m| m.fitness.value).collect();
        let report = Report {
            generation,
            best: best.fitness.value,
            median: median(&mut values),
            best_expr: best.expr.clone(),
            invalid: all.iter().filter(|m| m.fitness.invalid.is_some()).count(),
            evaluated,
            compile_s,
            evaluate_s,
            gp_s,
            transfer_s: (migration + gather_start.elapsed()).as_secs_f64(),
            seconds: start.elapsed().as_secs_f64(),
            ranks,
            front: (self.settings.objectives == Objectives::ErrorCost).then(|| pareto_front(&state).len()),
        };
        Ok(Some((state, report)))
    }

    /// Members from stored islands; fitness values are taken as stored.
    fn restore(&mut self, islands: &[Vec<StoredMember>]) -> anyhow::Result<Vec<Vec<Member>>> {
        islands
            .iter()
            .map(|island| {
                island
                    .iter()
                    .map(|s| {
                        let expr = parse_expr(&s.expr).with_context(|| format!("stored expression `{}`", s.expr))?;
                        self.memo.entry(s.key()).or_insert_with(|| s.fitness.clone());
                        Ok(Member { expr, text: s.expr.clone(), radius: s.radius, fitness: s.fitness.clone() })
                    })
                    .collect()
            })
            .collect()
    }
}

fn best_of(island: &[Member]) -> &Member {
    island.iter().min_by(|a, b| a.fitness.value.total_cmp(&b.fitness.value)).expect("non-empty island")
}

/// The valid members better than the noisy input that no other member
/// dominates in (error, cost), one per point, cheapest first (the most
/// accurate last).
pub fn pareto_front(state: &State) -> Vec<StoredMember> {
    let mut seen = std::collections::HashSet::new();
    let members: Vec<&StoredMember> = state
        .islands
        .iter()
        .flatten()
        .filter(|m| m.fitness.is_choice())
        .filter(|m| seen.insert(m.fitness.point_key()))
        .collect();
    let points: Vec<Vec<f64>> = members.iter().map(|m| m.fitness.objectives()).collect();
    let rank = pareto::fronts(&points);
    let mut front: Vec<StoredMember> =
        members.iter().zip(&rank).filter(|(_, &r)| r == 0).map(|(m, _)| (*m).clone()).collect();
    front.sort_by(|a, b| {
        let (pa, pb) = (a.fitness.objectives(), b.fitness.objectives());
        pa[1].total_cmp(&pb[1]).then(pa[0].total_cmp(&pb[0])).then(a.expr.cmp(&b.expr))
    });
    front
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
            if seen.insert(m.key()) {
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

#[cfg(test)]
mod tests {
    use super::transport::threads;
    use super::*;

    /// Fitness from the text alone: deterministic, cheap, different for different expressions.
    struct TextFitness;

    impl Evaluator for TextFitness {
        fn evaluate(&mut self, candidates: &[Candidate]) -> anyhow::Result<Vec<Fitness>> {
            Ok(candidates
                .iter()
                .map(|c| {
                    let text = c.expr.to_string();
                    let hash =
                        text.bytes().fold(1469598103934665603u64, |h, b| (h ^ b as u64).wrapping_mul(1099511628211));
                    let r = c.radius.unwrap_or(3) as f64;
                    Fitness::valid((hash % 10_000) as f64 / 10_000.0 / r + text.len() as f64 * 1e-4)
                        .with_cost(text.len() as f64 * (2.0 * r + 1.0).powi(2))
                })
                .collect())
        }
        fn take_time(&mut self) -> EvalTime {
            EvalTime::default()
        }
    }

    fn settings(islands: usize) -> Settings {
        Settings { islands, island_size: 8, generations: 6, migration_interval: 2, seed: 11, ..Settings::default() }
    }

    fn terminals() -> Terminals {
        Terminals {
            features: vec![Feature::Pixel, Feature::Color, Feature::Normal],
            variables: Vec::new(),
            constants: crate::lang::ops::THESIS_CONSTANTS.to_vec(),
        }
    }

    fn seed() -> Expr {
        parse_expr(crate::corpus::lookup("bilateral").unwrap()).unwrap()
    }

    fn multi(islands: usize) -> Settings {
        Settings { objectives: Objectives::ErrorCost, ..settings(islands) }
    }

    /// Every generation's whole population, from one process.
    fn in_process(islands: usize) -> Vec<State> {
        run_in_process(settings(islands))
    }

    fn run_in_process(settings: Settings) -> Vec<State> {
        let mut evaluator = TextFitness;
        let multi = settings.objectives == Objectives::ErrorCost;
        let mut engine = Engine::new(settings, terminals(), seed(), &mut evaluator).unwrap();
        if multi {
            engine.set_radii(1..=3);
        }
        let mut states = vec![engine.initial().unwrap().unwrap().0];
        for _ in 0..engine.settings.generations {
            states.push(engine.step().unwrap().unwrap().0);
        }
        states
    }

    /// The same, with the islands shared among `ranks` threads acting as processes.
    fn shared(islands: usize, ranks: usize) -> Vec<State> {
        run_shared(settings(islands), ranks)
    }

    fn run_shared(settings: Settings, ranks: usize) -> Vec<State> {
        let multi = settings.objectives == Objectives::ErrorCost;
        let results: Vec<Vec<State>> = std::thread::scope(|s| {
            let handles: Vec<_> = threads::job(ranks)
                .into_iter()
                .map(|transport| {
                    let settings = settings.clone();
                    s.spawn(move || {
                        let mut evaluator = TextFitness;
                        let generations = settings.generations;
                        let mut engine =
                            Engine::with_transport(settings, terminals(), seed(), &mut evaluator, Box::new(transport))
                                .unwrap();
                        if multi {
                            engine.set_radii(1..=3);
                        }
                        let mut states: Vec<State> = engine.initial().unwrap().into_iter().map(|(s, _)| s).collect();
                        for _ in 0..generations {
                            states.extend(engine.step().unwrap().map(|(s, _)| s));
                        }
                        states
                    })
                })
                .collect();
            handles.into_iter().map(|h| h.join().unwrap()).collect()
        });
        assert!(results[1..].iter().all(|r| r.is_empty()), "only the root sees the population");
        results.into_iter().next().unwrap()
    }

    fn texts(states: &[State]) -> Vec<Vec<Vec<String>>> {
        states.iter().map(|s| s.islands.iter().map(|i| i.iter().map(|m| m.key()).collect()).collect()).collect()
    }

    #[test]
    fn a_multi_objective_search_keeps_a_front_of_radii_and_shares_like_one_process() {
        let states = run_in_process(multi(4));
        let last = states.last().unwrap();
        let radii: std::collections::BTreeSet<u32> =
            last.islands.iter().flatten().map(|m| m.radius.expect("the radius is a gene")).collect();
        assert!(radii.iter().all(|r| (1..=3).contains(r)) && radii.len() > 1, "{radii:?}");
        let front = pareto_front(last);
        assert!(front.len() >= 2, "{front:?}");
        for a in &front {
            for b in &front {
                assert!(!pareto::dominates(&a.fitness.objectives(), &b.fitness.objectives()));
            }
        }
        let costs: Vec<f64> = front.iter().map(|m| m.fitness.cost.unwrap()).collect();
        assert!(costs.windows(2).all(|w| w[0] <= w[1]), "cheapest first: {costs:?}");
        // NSGA-II is elitist: the front's most accurate member never gets worse.
        let best = |s: &State| pareto_front(s).iter().map(|m| m.fitness.value).fold(f64::INFINITY, f64::min);
        assert!(states.windows(2).all(|w| best(&w[1]) <= best(&w[0])));
        assert_eq!(texts(&run_shared(multi(4), 3)), texts(&states));
    }

    /// A fitness relative to a baseline filter is above 1 wherever the
    /// baseline is better; such a member still filters (its error against
    /// the noisy input's is below 1) and is a trade-off on the front. Only
    /// what filters nothing is left off it.
    #[test]
    fn members_worse_than_a_fitness_baseline_stay_on_the_front() {
        let member = |expr: &str, value: f64, versus_noisy: f64, cost: f64| StoredMember {
            expr: expr.into(),
            fitness: Fitness::valid(value).with_versus_noisy(versus_noisy).with_cost(cost),
            radius: None,
        };
        let state = State {
            generation: 1,
            islands: vec![vec![
                member("seed", 1.0, 0.2, 100.0),
                member("cheap", 1.4, 0.3, 10.0),
                member("cheapest", 2.5, 0.5, 1.0),
                member("nothing", 5.0, 1.0, 0.5),
                member("dominated", 1.5, 0.31, 20.0),
            ]],
        };
        let front: Vec<String> = pareto_front(&state).into_iter().map(|m| m.expr).collect();
        assert_eq!(front, ["cheapest", "cheap", "seed"]);
        // Without the measure against the noisy input, the value itself says it (the thesis's rule).
        assert!(Fitness::valid(0.5).is_choice() && !Fitness::valid(1.0).is_choice());
    }

    #[test]
    fn error_islands_keep_the_full_radius_and_share_like_one_process() {
        let settings = Settings { error_islands: 1, ..multi(4) };
        let states = run_in_process(settings.clone());
        // Until the first migration brings other radii in, island 0 has the full radius only.
        for state in &states[..2] {
            assert!(state.islands[0].iter().all(|m| m.radius == Some(3)), "island 0 minimises error alone");
        }
        let later: std::collections::BTreeSet<u32> =
            states.last().unwrap().islands[1..].iter().flatten().filter_map(|m| m.radius).collect();
        assert!(later.len() > 1, "{later:?}");
        assert_eq!(texts(&run_shared(settings, 2)), texts(&states));
        assert!(Settings { error_islands: 5, ..multi(4) }.check().is_err());
    }

    #[test]
    fn the_single_objective_search_has_no_radius_gene() {
        let states = in_process(2);
        assert!(states.iter().flat_map(|s| s.islands.iter().flatten()).all(|m| m.radius.is_none()));
    }

    #[test]
    fn islands_shared_among_processes_evolve_as_in_one() {
        for islands in [4, 5] {
            let expected = in_process(islands);
            assert_eq!(expected.len(), 7);
            for ranks in 1..=islands {
                assert_eq!(texts(&shared(islands, ranks)), texts(&expected), "{islands} islands on {ranks} ranks");
            }
        }
    }

    #[test]
    fn migration_crosses_processes() {
        // Migration moves members between islands: without it, shared runs would agree trivially.
        let with = in_process(4);
        let mut evaluator = TextFitness;
        let mut engine =
            Engine::new(Settings { migration_interval: 0, ..settings(4) }, terminals(), seed(), &mut evaluator)
                .unwrap();
        engine.initial().unwrap();
        let mut without = Vec::new();
        for _ in 0..6 {
            without.push(engine.step().unwrap().unwrap().0);
        }
        assert_ne!(texts(&with[1..]), texts(&without), "migration changed nothing");
    }

    #[test]
    fn a_resumed_process_continues_exactly() {
        let expected = in_process(4);
        let mut evaluator = TextFitness;
        let mut engine = Engine::new(settings(4), terminals(), seed(), &mut evaluator).unwrap();
        engine.resume(&expected[3]).unwrap();
        let next = engine.step().unwrap().unwrap().0;
        assert_eq!(texts(&[next]), texts(&expected[4..5]));
        assert!(engine.resume(&State { generation: 3, islands: expected[3].islands[..2].to_vec() }).is_err());
    }

    #[test]
    fn more_processes_than_islands_is_an_error() {
        let mut evaluator = TextFitness;
        let transport = threads::job(3).into_iter().next().unwrap();
        let error = Engine::with_transport(settings(2), terminals(), seed(), &mut evaluator, Box::new(transport))
            .err()
            .expect("an error");
        assert!(error.to_string().contains("2 islands cannot be shared among 3 processes"), "{error}");
    }

    #[test]
    fn a_seed_longer_than_the_limit_is_refused_rather_than_left_unmoved() {
        // Every mutation of a seed over the limit would be too long and fall
        // back to the seed itself: the search would stand still.
        let mut evaluator = TextFitness;
        let long = Settings { max_length: seed().len() - 1, ..settings(2) };
        let error = Engine::new(long, terminals(), seed(), &mut evaluator).err().expect("an error");
        let said = error.to_string();
        assert!(
            said.contains(&format!("{} nodes, more than --max-length {}", seed().len(), seed().len() - 1)),
            "{said}"
        );
        let fits = Settings { max_length: seed().len(), ..settings(2) };
        assert!(Engine::new(fits, terminals(), seed(), &mut evaluator).is_ok());
    }
}
