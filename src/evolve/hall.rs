//! The hall of fame: its text (the named-expression format `filter --expr
//! @FILE` reads), and, after a run on tiles, its members scored again on
//! whole training images.

use anyhow::{Context, Result};
use serde::Serialize;

use crate::fitness::{FitnessRule, Scorer};
use crate::gp::{self, State};
use crate::named::{Entry, NamedFile};
use crate::pipeline::FilterPipeline;

/// A hall-of-fame member scored again on whole training images, after a run on tiles.
#[derive(Clone, Debug, Serialize)]
pub struct Rescored {
    pub expr: String,
    /// Its fitness on the run's tiles.
    pub fitness_on_tiles: f64,
    /// Its fitness on the whole training images (`None`: invalid there, with the reason in `invalid`).
    pub fitness: Option<f64>,
    pub invalid: Option<String>,
}

/// The hall of fame's fitness on `whole`'s scenes, member by member.
pub(super) fn rescore(whole: &mut Scorer<'_>, hall: &[(usize, gp::StoredMember)]) -> Result<Vec<Rescored>> {
    let mut unique: Vec<&gp::StoredMember> = Vec::new();
    for (_, m) in hall {
        if m.fitness.invalid.is_none() && !unique.iter().any(|u| u.expr == m.expr) {
            unique.push(m);
        }
    }
    let mut at = Vec::new();
    for m in &unique {
        let expr = crate::lang::parse_expr(&m.expr).context("hall of fame")?;
        at.push((expr, m.radius.unwrap_or(whole.radius())));
    }
    let errors = whole.errors_each(&at)?;
    Ok(unique
        .iter()
        .zip(&errors)
        .map(|(m, result)| {
            let fitness = whole.fitness(result);
            Rescored {
                expr: m.expr.clone(),
                fitness_on_tiles: m.fitness.value,
                fitness: fitness.as_ref().ok().copied(),
                invalid: fitness.err().map(|reason| reason.to_string()),
            }
        })
        .collect())
}

/// The hall of fame in the named-expression format `filter --expr @FILE` reads;
/// a multi-objective run's front follows as `front1` (cheapest) … `frontN`.
/// `rescored`, after a run on tiles: each member's fitness on whole training
/// images, which then orders the entries (the first is the one to use).
pub fn hall_of_fame(
    state: &State,
    k: usize,
    pipeline: &FilterPipeline,
    rule: &FitnessRule,
    front: &[gp::StoredMember],
    rescored: &[Rescored],
) -> NamedFile {
    let mut header = vec![
        "filterjit hall of fame: the best expressions of every island, best first.".to_string(),
        "Use one with `filterjit filter --expr @hall_of_fame.txt:NAME` (the first without :NAME);".into(),
        "each is filtered through the pipeline it was scored with (`# pipeline:` before it).".into(),
        format!("fitness: {}", rule.describe()),
    ];
    if !rescored.is_empty() {
        header.push("The search scored fitness on tiles; `fitness` below is on the whole training images.".into());
    }
    let entry = |name: String, m: &gp::StoredMember, notes: Vec<String>| Entry {
        name,
        text: m.expr.clone(),
        notes,
        pipeline: Some(*pipeline),
        radius: m.radius,
    };
    let whole = |expr: &str| rescored.iter().find(|r| r.expr == expr).map(|r| r.fitness.unwrap_or(f64::INFINITY));
    let mut members = gp::hall_of_fame(state, k);
    members.sort_by(|a, b| {
        let key = |m: &gp::StoredMember| whole(&m.expr).unwrap_or(m.fitness.value);
        key(&a.1).total_cmp(&key(&b.1))
    });
    let mut entries = Vec::new();
    let mut rank_in_island = vec![0usize; state.islands.len()];
    for (island, m) in members {
        rank_in_island[island] += 1;
        let parsed = crate::lang::parse_expr(&m.expr).ok();
        let len = parsed.as_ref().map_or(0, |e| e.len());
        let fitness = match (&m.fitness.invalid, rescored.iter().find(|r| r.expr == m.expr)) {
            (Some(reason), _) => format!("invalid ({reason})"),
            (None, Some(r)) => match (r.fitness, &r.invalid) {
                (Some(f), _) => format!("{f:.6} (on tiles {:.6})", r.fitness_on_tiles),
                (None, reason) => format!("invalid on whole images ({})", reason.as_deref().unwrap_or("?")),
            },
            (None, None) => format!("{:.6}", m.fitness.value),
        };
        let mut notes = vec![format!("fitness {fitness}, length {len}")];
        if let Some(simplified) = parsed.map(|e| crate::simplify::simplify(&e)) {
            // Beside the raw form that was scored: the same weights, for people.
            notes.push(format!("simplified (length {}): {simplified}", simplified.len()));
        }
        entries.push(entry(format!("island{island}_rank{}", rank_in_island[island]), &m, notes));
    }
    for (n, m) in front.iter().enumerate() {
        let cost = m.fitness.cost.unwrap_or(0.0);
        let mut notes = Vec::new();
        if n == 0 {
            notes.extend([
                String::new(),
                "The front of (error, modelled cost per pixel), cheapest first: no member is both".into(),
                "more accurate and cheaper than another (pareto.json has their measured times).".into(),
            ]);
        }
        notes.push(format!("fitness {:.6}, cost {cost:.0}", m.fitness.value));
        entries.push(entry(format!("front{}", n + 1), m, notes));
    }
    NamedFile { header, entries }
}
