//! `hrc-adapt experiment --replicate N`: power before participants (issue 14, point 5).
//!
//! Runs N seeded replications of the **simulated** experiment of one experiment file, each a
//! whole experiment in its own folder (`rep-01/`, …, every trial folder and report kept, so
//! nothing is lost and any replication can be inspected). Replication 1 uses the file's seed;
//! replication r > 1 the seed [`replication_seed`] derives from it and r, which draws a new
//! Williams schedule and new simulated operators. For each metric of the A/B comparison
//! (`aggregate::METRICS`) it then reports the distribution of the policy effect (the median
//! paired difference, and the rank-biserial r) over the replications, and the share of
//! replications in which the Wilcoxon test is significant at α = 0.05, raw and after Holm:
//! the power of that test at this sample size, **under the simulated operator's assumptions**
//! (a replication in which a metric could not be tested counts as not significant).
//!
//! Written to `<stamp>-replicate/`: `replications.csv` (one row per replication × metric),
//! `power.csv` and `power.md` (the power table, labelled SIMULATED).

use std::path::{Path, PathBuf};

use policies::SplitMix64;

use super::aggregate::{self, METRICS, PolicyTest};
use crate::Error;

/// Significance level of the power table.
pub(crate) const ALPHA: f64 = 0.05;

/// The seed of replication `r` (1-based) of an experiment with seed `seed`: `seed` itself for
/// r = 1 (so replication 1 is the plain experiment), else the first SplitMix64 output seeded
/// with `seed` mixed with r times the golden-ratio constant.
pub(crate) fn replication_seed(seed: u64, r: usize) -> u64 {
    if r <= 1 {
        return seed;
    }
    SplitMix64::new(seed ^ (r as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15)).next_u64()
}

/// One metric's figures in one replication.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Effect {
    /// Participant pairs [-].
    pub(crate) n_pairs: usize,
    /// Median paired difference a − b, in the metric's unit (NaN without pairs).
    pub(crate) median_difference: f64,
    /// Rank-biserial r (NaN when not tested).
    pub(crate) rank_biserial: f64,
    /// Wilcoxon p-value (NaN when not tested).
    pub(crate) p_value: f64,
    /// Holm-adjusted p-value (NaN when not tested).
    pub(crate) p_holm: f64,
}

impl Effect {
    /// The figures of one [`PolicyTest`].
    pub(crate) fn of(t: &PolicyTest) -> Effect {
        let (r, p) = t
            .wilcoxon
            .as_ref()
            .map_or((f64::NAN, f64::NAN), |w| (w.rank_biserial, w.p_value));
        Effect {
            n_pairs: t.n_pairs,
            median_difference: t.median_difference,
            rank_biserial: r,
            p_value: p,
            p_holm: t.p_holm.unwrap_or(f64::NAN),
        }
    }
}

/// One row of the power table.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct PowerRow {
    /// The metric (`aggregate::METRICS`).
    pub(crate) metric: &'static str,
    /// Replications [-].
    pub(crate) replications: usize,
    /// Of which the metric could be tested [-].
    pub(crate) tested: usize,
    /// Median, 2.5 % and 97.5 % quantiles of the median paired difference over the
    /// replications with pairs (the metric's unit).
    pub(crate) effect: [f64; 3],
    /// Median rank-biserial r over the tested replications [-].
    pub(crate) r_median: f64,
    /// Share of all replications with p < α [-].
    pub(crate) power_raw: f64,
    /// Share of all replications with Holm-adjusted p < α [-].
    pub(crate) power_holm: f64,
}

/// The power table from each replication's effects, `effects[r][m]` for metric `m` in
/// [`METRICS`] order.
pub(crate) fn power_table(effects: &[[Effect; METRICS.len()]]) -> Vec<PowerRow> {
    let n = effects.len();
    let sorted = |mut v: Vec<f64>| {
        v.retain(|x| x.is_finite());
        v.sort_by(f64::total_cmp);
        v
    };
    METRICS
        .iter()
        .enumerate()
        .map(|(m, &metric)| {
            let col: Vec<Effect> = effects.iter().map(|e| e[m]).collect();
            let diffs = sorted(col.iter().map(|e| e.median_difference).collect());
            let rs = sorted(col.iter().map(|e| e.rank_biserial).collect());
            let share = |p: fn(&Effect) -> f64| {
                if n == 0 {
                    f64::NAN
                } else {
                    col.iter().filter(|e| p(e) < ALPHA).count() as f64 / n as f64
                }
            };
            PowerRow {
                metric,
                replications: n,
                tested: col.iter().filter(|e| e.p_value.is_finite()).count(),
                effect: [0.5, 0.025, 0.975].map(|q| aggregate::quantile(&diffs, q)),
                r_median: aggregate::quantile(&rs, 0.5),
                power_raw: share(|e| e.p_value),
                power_holm: share(|e| e.p_holm),
            }
        })
        .collect()
}

/// A number for a CSV cell: empty when not finite.
fn cell(x: f64) -> String {
    if x.is_finite() {
        format!("{x}")
    } else {
        String::new()
    }
}

/// Writes `replications.csv`, `power.csv` and `power.md` into `dir`.
pub(crate) fn write(
    dir: &Path,
    policies: [&str; 2],
    seeds: &[u64],
    effects: &[[Effect; METRICS.len()]],
    table: &[PowerRow],
) -> crate::Result<()> {
    let mut csv = String::from(
        "replication,seed,metric,n_pairs,median_difference,rank_biserial,p_value,p_holm\n",
    );
    for (r, (seed, row)) in seeds.iter().zip(effects).enumerate() {
        for (metric, e) in METRICS.iter().zip(row) {
            csv.push_str(&format!(
                "{},{seed},{metric},{},{},{},{},{}\n",
                r + 1,
                e.n_pairs,
                cell(e.median_difference),
                cell(e.rank_biserial),
                cell(e.p_value),
                cell(e.p_holm)
            ));
        }
    }
    let path = dir.join("replications.csv");
    std::fs::write(&path, csv).map_err(Error::io("write", &path))?;

    let mut csv = String::from(
        "metric,replications,tested,effect_median,effect_q025,effect_q975,r_median,power_raw,\
         power_holm\n",
    );
    for t in table {
        csv.push_str(&format!(
            "{},{},{},{},{},{},{},{},{}\n",
            t.metric,
            t.replications,
            t.tested,
            cell(t.effect[0]),
            cell(t.effect[1]),
            cell(t.effect[2]),
            cell(t.r_median),
            cell(t.power_raw),
            cell(t.power_holm)
        ));
    }
    let path = dir.join("power.csv");
    std::fs::write(&path, csv).map_err(Error::io("write", &path))?;

    let path = dir.join("power.md");
    let n = seeds.len();
    let mut md = format!(
        "# SIMULATED power table: {} − {}\n\n\
         **SIMULATED.** {n} replications of the experiment with the simulated operator; the \
         power holds only under its assumptions (src/trial/operator.rs). Effect: the median \
         over participants of the paired difference {a} − {b} (per participant the mean over \
         conditions), its median and 2.5–97.5 % range over the replications. Power: the share \
         of the {n} replications with Wilcoxon p < {ALPHA} (a metric that could not be tested \
         counts as not significant), raw and after Holm across the metrics.\n\n\
         | metric | tested | effect median | effect 2.5–97.5 % | r median | power (raw) | power (Holm) |\n\
         |---|---|---|---|---|---|---|\n",
        policies[0],
        policies[1],
        a = policies[0],
        b = policies[1],
    );
    let f = |x: f64| {
        if x.is_finite() {
            format!("{x:.3}")
        } else {
            "–".into()
        }
    };
    for t in table {
        md.push_str(&format!(
            "| {} | {}/{} | {} | {} … {} | {} | {} | {} |\n",
            t.metric,
            t.tested,
            t.replications,
            f(t.effect[0]),
            f(t.effect[1]),
            f(t.effect[2]),
            f(t.r_median),
            f(t.power_raw),
            f(t.power_holm)
        ));
    }
    std::fs::write(&path, md).map_err(Error::io("write", &path))?;
    Ok(())
}

/// What [`run_replications`] did.
#[derive(Debug)]
pub(crate) struct ReplicateOutcome {
    /// The folder holding every replication and the power table.
    pub(crate) dir: PathBuf,
    /// Trials run over all replications, and of which failed.
    pub(crate) trials: usize,
    /// See `trials`.
    pub(crate) failed: usize,
    /// The power table.
    pub(crate) table: Vec<PowerRow>,
}

/// Runs `n` replications of the experiment `config_path` into a new folder (`wanted`, or
/// `wanted-2`, …), then writes the power table. Progress: a line per replication on stderr.
pub(crate) fn run_replications(
    config_path: &Path,
    wanted: &Path,
    jobs: usize,
    n: usize,
    show_progress: bool,
) -> crate::Result<ReplicateOutcome> {
    let cfg = super::ExperimentConfig::from_file(config_path)?;
    let dir = crate::trial::create_run_dir(wanted)?;
    let started = std::time::Instant::now();
    let (mut trials, mut failed) = (0, 0);
    let mut seeds = Vec::with_capacity(n);
    let mut effects = Vec::with_capacity(n);
    for r in 1..=n {
        let seed = replication_seed(cfg.seed, r);
        let out = super::run_experiment_seeded(
            config_path,
            &dir.join(format!("rep-{r:02}")),
            jobs,
            show_progress,
            Some(seed),
        )?;
        trials += out.trials;
        failed += out.failed;
        let outcomes = aggregate::read_outcomes(&out.dir)?;
        let tests = aggregate::compare_policies(&outcomes, &cfg.policies[0], &cfg.policies[1])?;
        let mut row = [Effect {
            n_pairs: 0,
            median_difference: f64::NAN,
            rank_biserial: f64::NAN,
            p_value: f64::NAN,
            p_holm: f64::NAN,
        }; METRICS.len()];
        for t in &tests {
            row[t.metric] = Effect::of(t);
        }
        seeds.push(seed);
        effects.push(row);
        eprintln!(
            "[simulation] replication {r}/{n} (seed {seed}): {} trials ({} failed), {:.0} s \
             elapsed",
            out.trials,
            out.failed,
            started.elapsed().as_secs_f64()
        );
    }
    let table = power_table(&effects);
    write(
        &dir,
        [&cfg.policies[0], &cfg.policies[1]],
        &seeds,
        &effects,
        &table,
    )?;
    Ok(ReplicateOutcome {
        dir,
        trials,
        failed,
        table,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn effect(d: f64, r: f64, p: f64, holm: f64) -> Effect {
        Effect {
            n_pairs: 8,
            median_difference: d,
            rank_biserial: r,
            p_value: p,
            p_holm: holm,
        }
    }

    #[test]
    fn replication_1_is_the_plain_experiment_and_the_others_differ() {
        assert_eq!(replication_seed(2026, 1), 2026);
        let seeds: Vec<u64> = (1..=20).map(|r| replication_seed(2026, r)).collect();
        let mut unique = seeds.clone();
        unique.sort_unstable();
        unique.dedup();
        assert_eq!(unique.len(), 20, "{seeds:?}");
        // Deterministic: the same seed and r give the same replication.
        assert_eq!(replication_seed(2026, 7), seeds[6]);
    }

    /// Worked by hand: four replications of metric 0 with median differences −3, −1, 2, NaN
    /// (no pairs in the last), r −0.8, −0.2, 0.4, NaN and p 0.01, 0.2, 0.04, NaN (Holm 0.07,
    /// 0.2, 0.04, NaN).
    /// - tested: 3 of 4 (the NaN p).
    /// - effect over {−3, −1, 2} (type-7 quantiles): median −1; 2.5 %: h = 2·0.025 = 0.05,
    ///   −3 + 0.05·2 = −2.9; 97.5 %: h = 1.95, −1 + 0.95·3 = 1.85.
    /// - r median over {−0.8, −0.2, 0.4}: −0.2.
    /// - power raw: p < 0.05 in 2 of 4 = 0.5 (0.01 and 0.04; the untested one counts as not
    ///   significant); Holm: 1 of 4 = 0.25 (0.04).
    #[test]
    fn the_power_table_matches_a_hand_computed_example() {
        let blank = effect(f64::NAN, f64::NAN, f64::NAN, f64::NAN);
        let mut reps = vec![[blank; METRICS.len()]; 4];
        reps[0][0] = effect(-3.0, -0.8, 0.01, 0.07);
        reps[1][0] = effect(-1.0, -0.2, 0.2, 0.2);
        reps[2][0] = effect(2.0, 0.4, 0.04, 0.04);
        reps[3][0] = Effect {
            n_pairs: 0,
            ..blank
        };
        let t = &power_table(&reps)[0];
        assert_eq!(t.metric, METRICS[0]);
        assert_eq!((t.replications, t.tested), (4, 3));
        let close = |a: f64, b: f64| (a - b).abs() < 1e-12;
        assert!(close(t.effect[0], -1.0), "{:?}", t.effect);
        assert!(close(t.effect[1], -2.9), "{:?}", t.effect);
        assert!(close(t.effect[2], 1.85), "{:?}", t.effect);
        assert!(close(t.r_median, -0.2));
        assert!(close(t.power_raw, 0.5));
        assert!(close(t.power_holm, 0.25));
        // A metric never tested: nothing significant, no effect.
        let u = &power_table(&reps)[1];
        assert_eq!(u.tested, 0);
        assert_eq!((u.power_raw, u.power_holm), (0.0, 0.0));
        assert!(u.effect[0].is_nan());
    }

    /// p exactly α is not significant (p < α).
    #[test]
    fn p_equal_to_alpha_is_not_significant() {
        let reps = vec![[effect(1.0, 0.5, ALPHA, ALPHA); METRICS.len()]];
        let t = &power_table(&reps)[0];
        assert_eq!((t.power_raw, t.power_holm), (0.0, 0.0));
    }
}
