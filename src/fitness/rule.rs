//! How one candidate's relMSE on each training scene becomes its one training
//! fitness: each scene's error is divided by a reference error on that scene
//! and the ratios are pooled over the scenes.
//!
//! The thesis (section 3.2.3) divides by the noisy input's relMSE and takes the
//! mean. A user who wants a filter that beats the one they have on *every*
//! scene divides by that filter's relMSE instead (`--fitness-relative-to`) and
//! pools by the worst scene (`--fitness-pool worst`): a fitness below 1 then
//! means better than the baseline everywhere the search looked. `worst` stalls
//! where no small change helps every scene at once, and `mean` lets one scene
//! where the baseline fails badly buy losses on all the others; `guarded`
//! takes the mean but charges every scene's loss against the baseline in full
//! (docs/JOURNAL.md, "Fitness that keeps every scene").
//!
//! relMSE divides each pixel's error by its reference value squared, so a
//! weight that averages the few bright pixels carrying a render's light into
//! their dark neighbours costs little relMSE and much light. With
//! `light_tolerance` set, each scene's error is charged for the light the
//! filter moved ([`charged`]) before it is divided and pooled.

use serde::{Deserialize, Serialize};

use crate::metrics;

/// How the per-scene ratios are pooled.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Pool {
    /// Their mean (the thesis's).
    #[default]
    Mean,
    /// The largest: the scene where the candidate does worst.
    Worst,
    /// The mean, plus each ratio's excess over 1 (the reference's own error)
    /// in full: with N scenes a loss of x on one scene is offset only by
    /// gains of (N + 1)·x over the others.
    Guarded,
}

impl Pool {
    pub const NAMES: &'static str = "mean, worst, guarded";

    /// Pool `relmse[i] / divisor[i]` (the divisor floored, [`metrics::normalised`]).
    pub fn combine(self, relmse: impl IntoIterator<Item = f64>, divisors: &[f64]) -> f64 {
        let ratios = relmse.into_iter().zip(divisors).map(|(e, d)| metrics::normalised(e, *d));
        let mean = |ratios: &[f64]| ratios.iter().sum::<f64>() / ratios.len().max(1) as f64;
        match self {
            Pool::Mean => mean(&ratios.collect::<Vec<_>>()),
            Pool::Worst => ratios.fold(0.0, f64::max),
            Pool::Guarded => {
                let ratios: Vec<f64> = ratios.collect();
                mean(&ratios) + ratios.iter().map(|r| (r - 1.0).max(0.0)).sum::<f64>()
            }
        }
    }
}

impl std::fmt::Display for Pool {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Pool::Mean => "mean",
            Pool::Worst => "worst",
            Pool::Guarded => "guarded",
        })
    }
}

impl std::str::FromStr for Pool {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "mean" => Ok(Pool::Mean),
            "worst" => Ok(Pool::Worst),
            "guarded" => Ok(Pool::Guarded),
            _ => Err(format!("`{s}` is no way to pool scenes (one of: {})", Pool::NAMES)),
        }
    }
}

/// A run's fitness rule; kept in its checkpoint.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct FitnessRule {
    /// The canonical text of the baseline expression whose relMSE, through
    /// the run's own pipeline and on the same pixels, divides each scene's;
    /// the noisy input's when `None`.
    #[serde(default)]
    pub relative_to: Option<String>,
    #[serde(default)]
    pub pool: Pool,
    /// Charge each scene's error for the light the filter moved, with this
    /// tolerance ([`charged`]); relMSE alone when `None` (the thesis's).
    #[serde(default)]
    pub light_tolerance: Option<f64>,
}

/// A scene's relMSE charged for the light the filter moved:
/// `relmse · (1 + (ln(light) / tolerance)²)`, where `light` is the filtered
/// image's mean luminance over the noisy input's on the same pixels. The
/// noisy input is the unbiased estimate, so this is the bias the filter
/// itself adds, not the sampling error of four samples, which no filter can
/// know. With tolerance 0.05 a loss of 5 % doubles the error and one of 1 %
/// adds 4 %. A black noisy input charges nothing; a black output is charged
/// as one a million times darker.
pub fn charged(relmse: f64, luminance: f64, noisy_luminance: f64, tolerance: Option<f64>) -> f64 {
    match (tolerance, light_moved(luminance, noisy_luminance)) {
        (Some(tolerance), Some(light)) if tolerance > 0.0 => {
            relmse * (1.0 + (light.clamp(1e-6, 1e6).ln() / tolerance).powi(2))
        }
        _ => relmse,
    }
}

/// The light a filter moved: its output's mean luminance over the noisy
/// input's (`None` where the input is black).
pub fn light_moved(luminance: f64, noisy_luminance: f64) -> Option<f64> {
    (noisy_luminance > 0.0).then(|| luminance / noisy_luminance)
}

impl FitnessRule {
    /// The thesis's rule: mean of relMSE / noisy relMSE.
    pub fn is_thesis(&self) -> bool {
        *self == FitnessRule::default()
    }

    /// In words, for logs and the hall of fame.
    pub fn describe(&self) -> String {
        let against = match &self.relative_to {
            None => "the noisy input's relMSE".to_string(),
            Some(e) => format!("the relMSE of `{e}`"),
        };
        let pool = match self.pool {
            Pool::Mean => "mean over scenes",
            Pool::Worst => "worst scene",
            Pool::Guarded => "mean over scenes plus every loss against it in full",
        };
        let light = match self.light_tolerance {
            None => String::new(),
            Some(t) => format!(", each scene's error charged for the light it moves (tolerance {t})"),
        };
        format!("relMSE / {against}, {pool}{light}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pools_are_the_mean_and_the_worst_ratio() {
        let divisors = [2.0, 0.5, 1.0];
        assert_eq!(Pool::Mean.combine([1.0, 1.0, 1.0], &divisors), (0.5 + 2.0 + 1.0) / 3.0);
        assert_eq!(Pool::Worst.combine([1.0, 1.0, 1.0], &divisors), 2.0);
        // The divisor is floored as everywhere else: a perfect baseline divides by the floor.
        assert!(Pool::Worst.combine([1e-3], &[0.0]).is_finite());
        assert_eq!("worst".parse::<Pool>(), Ok(Pool::Worst));
        assert!("max".parse::<Pool>().unwrap_err().contains("mean, worst"));
    }

    #[test]
    fn light_moved_is_charged_both_ways_and_only_when_asked() {
        assert_eq!(charged(0.1, 0.5, 1.0, None), 0.1);
        assert_eq!(charged(0.1, 1.0, 1.0, Some(0.05)), 0.1);
        // A loss of a tolerance's worth (in log terms) doubles the error; a gain the same.
        let lost = charged(0.1, (-0.05f64).exp(), 1.0, Some(0.05));
        let gained = charged(0.1, 0.05f64.exp(), 1.0, Some(0.05));
        assert!((lost - 0.2).abs() < 1e-12 && (gained - 0.2).abs() < 1e-12, "{lost} {gained}");
        // Charged against the noisy input's light, not an absolute level.
        assert_eq!(charged(0.1, 2.0, 2.0, Some(0.05)), 0.1);
        // A black output is finite; a black input charges nothing.
        assert!(charged(0.1, 0.0, 1.0, Some(0.05)).is_finite() && charged(0.1, 0.0, 1.0, Some(0.05)) > 1e3);
        assert_eq!(charged(0.1, 0.3, 0.0, Some(0.05)), 0.1);
        let rule = FitnessRule { light_tolerance: Some(0.05), ..FitnessRule::default() };
        assert!(!rule.is_thesis() && rule.describe().contains("light"));
    }

    #[test]
    fn guarded_charges_every_loss_in_full() {
        let ones = [1.0; 4];
        // Better everywhere: the mean.
        assert_eq!(Pool::Guarded.combine([0.9, 0.8, 1.0, 0.9], &ones), Pool::Mean.combine([0.9, 0.8, 1.0, 0.9], &ones));
        // One scene twice as good buys no 5 % loss on the other three, which `mean` would take:
        // a loss is offset only by gains N + 1 times as large.
        let trade = [0.5, 1.05, 1.05, 1.05];
        assert!(Pool::Mean.combine(trade, &ones) < 1.0);
        let guarded = Pool::Guarded.combine(trade, &ones);
        assert!((guarded - (0.9125 + 0.15)).abs() < 1e-12, "{guarded}");
        // A loss of x on one of N scenes against gains of x on every other still costs.
        assert!(Pool::Guarded.combine([1.02, 0.98, 0.98, 0.98], &ones) > 1.0);
        assert_eq!("guarded".parse::<Pool>(), Ok(Pool::Guarded));
    }
}
