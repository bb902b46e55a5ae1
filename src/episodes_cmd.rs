//! `hrc-adapt episodes`: the assessor's hesitation against the simulated operator's, episode by
//! episode, over seeds × conditions (issue 14, point 2). **SIMULATED**: the ground truth is the
//! simulated operator's, not a person's.
//!
//! 1. Runs one simulated trial per seed × condition (the same trial `hrc-adapt trial --seed S
//!    --condition L --policy P` runs: participant `P00`, the simulated robot) into
//!    `<out-root>/<stamp>-episodes/<seed>-<condition>-<policy>/`, on `--jobs` workers.
//! 2. Reads every trial's `summary.json` `hesitation_episodes` (definitions in
//!    `src/trial/hesitation_episodes.rs`: recall, precision, onset delay, every episode).
//! 3. Writes `trials.csv` (one row per trial), `episodes.csv` (one row per episode, ground
//!    truth and assessed) and `episodes.md`: recall and precision pooled over the episodes of
//!    each condition and of all trials, the onset delay's median and quartiles, where the
//!    unmatched assessed episodes happened (the task phase), and the targets (recall
//!    and precision ≥ 0.8, median onset delay ≤ 0.5 s) as met or not.
//!
//! A failed trial is reported and left out of the tables; the command then exits non-zero after
//! writing everything.

use std::fmt::Write as _;
use std::io::IsTerminal as _;
use std::path::{Path, PathBuf};

use clap::Args;
use policies::{Condition, PolicyKind};

use crate::Error;
use crate::experiment::{PlannedTrial, TrialRun, run_trials};
use crate::trial::config::TrialConfig;
use crate::trial::episodes::{HesitationEpisodes, median};

/// The targets: recall and precision at least this [-] …
pub(crate) const TARGET_RATIO: f64 = 0.8;
/// … and the median onset delay at most this [s].
pub(crate) const TARGET_DELAY_S: f64 = 0.5;

/// Arguments of `hrc-adapt episodes`.
#[derive(Debug, Args)]
pub struct EpisodesArgs {
    /// Seeds of the simulated operator: a range `1-10` or a list `1,4,7` (1 to 1000 of them).
    #[arg(long, default_value = "1-10", value_parser = parse_seeds)]
    seeds: Seeds,
    /// Task conditions, comma-separated.
    #[arg(long, default_value = "L1,L2,L3", value_delimiter = ',', value_parser = parse_condition)]
    conditions: Vec<Condition>,
    /// Policy of every trial (`adaptive`, `fixed`, …).
    #[arg(long, default_value = "adaptive", value_parser = parse_policy)]
    policy: PolicyKind,
    /// Trial configuration (default: the shipped config/trial.toml).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Folder under which `<timestamp>-episodes/` is created.
    #[arg(long, default_value = "runs")]
    out_root: PathBuf,
    /// Trials run in parallel (default: the available cores), 1..=256.
    #[arg(long, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=256))]
    jobs: Option<usize>,
}

/// A list of seeds.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Seeds(pub(crate) Vec<u64>);

/// `--seeds`: `A-B` (inclusive, A ≤ B) or `a,b,c`; 1 to 1000 distinct seeds.
pub(crate) fn parse_seeds(s: &str) -> Result<Seeds, String> {
    let bad = || format!("seeds are a range `1-10` or a list `1,4,7` of integers, got {s:?}");
    let seeds: Vec<u64> = if let Some((a, b)) = s.split_once('-') {
        let (a, b): (u64, u64) = (
            a.trim().parse().map_err(|_| bad())?,
            b.trim().parse().map_err(|_| bad())?,
        );
        if a > b {
            return Err(format!(
                "the range {s:?} is empty (its start is after its end)"
            ));
        }
        if b - a >= 1000 {
            return Err(format!("{s:?} has more than 1000 seeds"));
        }
        (a..=b).collect()
    } else {
        s.split(',')
            .map(|x| x.trim().parse::<u64>().map_err(|_| bad()))
            .collect::<Result<_, _>>()?
    };
    let mut sorted = seeds.clone();
    sorted.sort_unstable();
    sorted.dedup();
    if sorted.len() != seeds.len() {
        return Err(format!("{s:?} names a seed twice"));
    }
    if seeds.is_empty() || seeds.len() > 1000 {
        return Err(format!("{s:?} must name 1 to 1000 seeds"));
    }
    Ok(Seeds(seeds))
}

fn parse_condition(s: &str) -> Result<Condition, String> {
    Condition::ALL
        .into_iter()
        .find(|c| c.as_str() == s.trim())
        .ok_or_else(|| format!("a condition is L1, L2 or L3, got {s:?}"))
}

fn parse_policy(s: &str) -> Result<PolicyKind, String> {
    s.parse::<PolicyKind>().map_err(|e| e.to_string())
}

/// One trial's episodes, as read back from its `summary.json`.
#[derive(Debug, Clone)]
pub(crate) struct TrialEpisodes {
    /// Seed.
    pub(crate) seed: u64,
    /// Condition.
    pub(crate) condition: Condition,
    /// The trial's `hesitation_episodes`.
    pub(crate) episodes: HesitationEpisodes,
    /// `hesitation_share.assessed` and `.ground_truth` [-].
    pub(crate) share: (Option<f64>, Option<f64>),
}

/// Pooled figures of a set of trials.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Pooled {
    /// Trials [-].
    pub(crate) trials: usize,
    /// Ground-truth episodes, of them detected [-].
    pub(crate) truth: u64,
    /// See `truth`.
    pub(crate) detected: u64,
    /// Assessed episodes, of them matched [-].
    pub(crate) assessed: u64,
    /// See `assessed`.
    pub(crate) matched: u64,
    /// Onset delays of the detected episodes [s], sorted.
    pub(crate) delays: Vec<f64>,
    /// Attributed onsets of the detected episodes [s], sorted.
    pub(crate) attributed: Vec<f64>,
    /// Unmatched assessed episodes by task phase (`-` before the first phase), sorted by name.
    pub(crate) unmatched_by_phase: Vec<(String, u64)>,
}

impl Pooled {
    /// Pools `trials`' episodes.
    pub(crate) fn of<'a>(trials: impl IntoIterator<Item = &'a TrialEpisodes>) -> Pooled {
        let mut p = Pooled {
            trials: 0,
            truth: 0,
            detected: 0,
            assessed: 0,
            matched: 0,
            delays: Vec::new(),
            attributed: Vec::new(),
            unmatched_by_phase: Vec::new(),
        };
        let mut by_phase = std::collections::BTreeMap::<String, u64>::new();
        for t in trials {
            let e = &t.episodes;
            p.trials += 1;
            p.truth += e.ground_truth;
            p.detected += e.detected;
            p.assessed += e.assessed;
            p.matched += e.matched;
            p.delays
                .extend(e.truth_episodes.iter().filter_map(|x| x.delay_s));
            p.attributed
                .extend(e.truth_episodes.iter().filter_map(|x| x.attributed_onset_s));
            for a in e.assessed_episodes.iter().filter(|a| !a.matched) {
                *by_phase
                    .entry(a.phase.clone().unwrap_or_else(|| "-".into()))
                    .or_default() += 1;
            }
        }
        p.delays.sort_by(f64::total_cmp);
        p.attributed.sort_by(f64::total_cmp);
        p.unmatched_by_phase = by_phase.into_iter().collect();
        p
    }

    /// Σ detected / Σ ground truth [-].
    pub(crate) fn recall(&self) -> Option<f64> {
        (self.truth > 0).then(|| self.detected as f64 / self.truth as f64)
    }

    /// Σ matched / Σ assessed [-].
    pub(crate) fn precision(&self) -> Option<f64> {
        (self.assessed > 0).then(|| self.matched as f64 / self.assessed as f64)
    }
}

/// Runs `hrc-adapt episodes`.
pub fn run(args: EpisodesArgs) -> crate::Result<()> {
    let jobs = args.jobs.unwrap_or_else(|| {
        std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get)
    });
    let trial_config = match &args.config {
        Some(p) => TrialConfig::from_file(p)?,
        None => TrialConfig::shipped()?,
    };
    let wanted = args
        .out_root
        .join(format!("{}-episodes", crate::trial::wall_stamp()));
    let out = run_episodes(
        &args.seeds.0,
        &args.conditions,
        args.policy,
        &trial_config,
        &wanted,
        jobs,
        std::io::stderr().is_terminal(),
    )?;
    let all = Pooled::of(&out.trials);
    let f = |x: Option<f64>| x.map_or("-".into(), |v| format!("{v:.3}"));
    eprintln!(
        "[simulation] {} trials ({} failed): recall {} ({}/{}), precision {} ({}/{}), median \
         onset delay {} s; {}",
        out.runs,
        out.failed,
        f(all.recall()),
        all.detected,
        all.truth,
        f(all.precision()),
        all.matched,
        all.assessed,
        f(median(&all.delays)),
        out.dir.join("episodes.md").display()
    );
    println!("{}", out.dir.display());
    ensure!(
        out.failed == 0,
        Error::ExperimentFailed {
            failed: out.failed,
            trials: out.runs,
            report: out.dir.join("episodes.md"),
            dir: out.dir,
        }
    );
    Ok(())
}

/// What [`run_episodes`] did.
#[derive(Debug)]
pub(crate) struct EpisodesOutcome {
    /// The folder.
    pub(crate) dir: PathBuf,
    /// Trials run, of them failed.
    pub(crate) runs: usize,
    /// See `runs`.
    pub(crate) failed: usize,
    /// The trials read back, in seed × condition order.
    pub(crate) trials: Vec<TrialEpisodes>,
}

/// Runs the trials into a new folder at `wanted` and writes the tables (module docs).
pub(crate) fn run_episodes(
    seeds: &[u64],
    conditions: &[Condition],
    policy: PolicyKind,
    trial_config: &TrialConfig,
    wanted: &Path,
    jobs: usize,
    show_progress: bool,
) -> crate::Result<EpisodesOutcome> {
    ensure!(
        !conditions.is_empty(),
        Error::usage("--conditions", "name at least one condition")
    );
    let dir = crate::trial::create_run_dir(wanted)?;
    // Each trial its own session, so they spread over the workers.
    let sessions: Vec<Vec<PlannedTrial>> = seeds
        .iter()
        .flat_map(|&seed| {
            conditions.iter().map(move |&condition| {
                vec![PlannedTrial {
                    participant: "P00".into(),
                    position: 1,
                    condition,
                    policy,
                    square_row: 0,
                    seed,
                    folder: folder(seed, condition, policy),
                }]
            })
        })
        .collect();
    let total = sessions.len();
    let bar = if show_progress {
        indicatif::ProgressBar::new(total as u64)
    } else {
        indicatif::ProgressBar::hidden()
    };
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "[simulation] {bar:30} {pos}/{len} trials, {elapsed} elapsed, ETA {eta} {msg}",
        )
        .map_err(|e| Error::data("progress template", e.to_string()))?,
    );
    let mut failed = 0;
    let runs: Vec<TrialRun> = run_trials(sessions, trial_config, &dir, jobs, &mut |r| {
        if let Some(e) = &r.error {
            failed += 1;
            bar.println(format!("trial {} failed: {e}", r.trial.folder));
            bar.set_message(format!("({failed} failed)"));
        }
        bar.inc(1);
    });
    bar.finish_and_clear();
    let mut trials = Vec::new();
    for r in runs.iter().filter(|r| r.error.is_none()) {
        trials.push(read_trial(
            &dir.join(&r.trial.folder),
            r.trial.seed,
            r.trial.condition,
        )?);
    }
    write_tables(&dir, &trials, conditions, policy, runs.len(), failed)?;
    Ok(EpisodesOutcome {
        dir,
        runs: runs.len(),
        failed,
        trials,
    })
}

/// A trial's folder name: `s001-L2-adaptive`.
pub(crate) fn folder(seed: u64, condition: Condition, policy: PolicyKind) -> String {
    format!("s{seed:03}-{condition}-{policy}")
}

/// Reads one trial folder's `summary.json`.
pub(crate) fn read_trial(
    dir: &Path,
    seed: u64,
    condition: Condition,
) -> crate::Result<TrialEpisodes> {
    let path = dir.join(crate::trial::SUMMARY_FILE);
    let text = std::fs::read_to_string(&path).map_err(Error::io("read", &path))?;
    let mut v: serde_json::Value =
        serde_json::from_str(&text).map_err(Error::json("parse", path.display()))?;
    let share = |k: &str| v["hesitation_share"][k].as_f64();
    let share = (share("assessed"), share("ground_truth"));
    let episodes = serde_json::from_value(v["hesitation_episodes"].take())
        .map_err(Error::json("read hesitation_episodes of", path.display()))?;
    Ok(TrialEpisodes {
        seed,
        condition,
        episodes,
        share,
    })
}

fn csv_opt(x: Option<f64>) -> String {
    x.map_or(String::new(), |v| v.to_string())
}

/// Writes `trials.csv`, `episodes.csv` and `episodes.md` into `dir`.
pub(crate) fn write_tables(
    dir: &Path,
    trials: &[TrialEpisodes],
    conditions: &[Condition],
    policy: PolicyKind,
    runs: usize,
    failed: usize,
) -> crate::Result<()> {
    let path = dir.join("trials.csv");
    let mut w = csv::Writer::from_path(&path).map_err(Error::csv("create", &path))?;
    w.write_record([
        "seed",
        "condition",
        "policy",
        "ground_truth",
        "detected",
        "recall",
        "assessed",
        "matched",
        "precision",
        "onset_delay_median_s",
        "hesitation_share_assessed",
        "hesitation_share_ground_truth",
    ])
    .map_err(Error::csv("write", &path))?;
    for t in trials {
        let e = &t.episodes;
        w.write_record([
            t.seed.to_string(),
            t.condition.to_string(),
            policy.to_string(),
            e.ground_truth.to_string(),
            e.detected.to_string(),
            csv_opt(e.recall),
            e.assessed.to_string(),
            e.matched.to_string(),
            csv_opt(e.precision),
            csv_opt(e.onset_delay_median_s),
            csv_opt(t.share.0),
            csv_opt(t.share.1),
        ])
        .map_err(Error::csv("write", &path))?;
    }
    w.flush().map_err(Error::io("write", &path))?;

    let path = dir.join("episodes.csv");
    let mut w = csv::Writer::from_path(&path).map_err(Error::csv("create", &path))?;
    w.write_record([
        "seed",
        "condition",
        "kind",
        "start_s",
        "end_s",
        "detected_s",
        "delay_s",
        "attributed_onset_s",
        "matched",
        "phase",
    ])
    .map_err(Error::csv("write", &path))?;
    for t in trials {
        for x in &t.episodes.truth_episodes {
            w.write_record([
                t.seed.to_string(),
                t.condition.to_string(),
                "ground_truth".into(),
                x.start_s.to_string(),
                x.end_s.to_string(),
                csv_opt(x.detected_s),
                csv_opt(x.delay_s),
                csv_opt(x.attributed_onset_s),
                x.detected_s.is_some().to_string(),
                String::new(),
            ])
            .map_err(Error::csv("write", &path))?;
        }
        for a in &t.episodes.assessed_episodes {
            w.write_record([
                t.seed.to_string(),
                t.condition.to_string(),
                "assessed".into(),
                a.start_s.to_string(),
                a.end_s.to_string(),
                a.detected_s.to_string(),
                String::new(),
                String::new(),
                a.matched.to_string(),
                a.phase.clone().unwrap_or_default(),
            ])
            .map_err(Error::csv("write", &path))?;
        }
    }
    w.flush().map_err(Error::io("write", &path))?;

    let path = dir.join("episodes.md");
    std::fs::write(&path, markdown(trials, conditions, policy, runs, failed))
        .map_err(Error::io("write", &path))?;
    Ok(())
}

/// `episodes.md`.
pub(crate) fn markdown(
    trials: &[TrialEpisodes],
    conditions: &[Condition],
    policy: PolicyKind,
    runs: usize,
    failed: usize,
) -> String {
    let f3 = |x: Option<f64>| x.map_or("-".into(), |v| format!("{v:.3}"));
    let q =
        |v: &[f64], p: f64| (!v.is_empty()).then(|| crate::experiment::aggregate::quantile(v, p));
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# Hesitation episodes: assessed against SIMULATED ground truth\n\n\
         **SIMULATED**: the ground truth is the simulated operator's (`src/trial/operator.rs`), \
         not a person's. Policy `{policy}`, {runs} trials ({failed} failed, left out). \
         Definitions: `src/trial/hesitation_episodes.rs`. Targets (issue 14): recall and \
         precision ≥ {TARGET_RATIO}, median onset delay ≤ {TARGET_DELAY_S} s.\n"
    );
    let _ = writeln!(
        s,
        "| trials | ground truth | detected | recall | assessed | matched | precision | onset \
         delay median [s] | q25–q75 [s] | attributed onset median [s] |\n\
         |---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
    );
    let mut rows: Vec<(String, Pooled)> = conditions
        .iter()
        .map(|c| {
            (
                c.to_string(),
                Pooled::of(trials.iter().filter(|t| t.condition == *c)),
            )
        })
        .collect();
    rows.push(("all".into(), Pooled::of(trials)));
    for (name, p) in &rows {
        let _ = writeln!(
            s,
            "| {name} ({}) | {} | {} | {} | {} | {} | {} | {} | {}–{} | {} |",
            p.trials,
            p.truth,
            p.detected,
            f3(p.recall()),
            p.assessed,
            p.matched,
            f3(p.precision()),
            f3(median(&p.delays)),
            f3(q(&p.delays, 0.25)),
            f3(q(&p.delays, 0.75)),
            f3(median(&p.attributed)),
        );
    }
    let all = &rows[rows.len() - 1].1;
    let verdict = |ok: Option<bool>| match ok {
        Some(true) => "met",
        Some(false) => "**not met**",
        None => "not measurable",
    };
    let _ = writeln!(
        s,
        "\n- recall ≥ {TARGET_RATIO}: {}\n- precision ≥ {TARGET_RATIO}: {}\n- median onset delay \
         ≤ {TARGET_DELAY_S} s: {}\n",
        verdict(all.recall().map(|r| r >= TARGET_RATIO)),
        verdict(all.precision().map(|r| r >= TARGET_RATIO)),
        verdict(median(&all.delays).map(|d| d <= TARGET_DELAY_S)),
    );
    let _ = writeln!(
        s,
        "Unmatched assessed episodes, by the robot task phase when they were detected:\n"
    );
    if all.unmatched_by_phase.is_empty() {
        let _ = writeln!(s, "none");
    } else {
        let _ = writeln!(s, "| phase | episodes |\n|---|---:|");
        for (phase, n) in &all.unmatched_by_phase {
            let _ = writeln!(s, "| {phase} | {n} |");
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trial::episodes::{AssessedEpisode, TruthEpisode};

    #[test]
    fn seeds_parse_as_a_range_or_a_list_and_bad_input_is_refused() {
        assert_eq!(parse_seeds("1-3"), Ok(Seeds(vec![1, 2, 3])));
        assert_eq!(parse_seeds("7"), Ok(Seeds(vec![7])));
        assert_eq!(parse_seeds("4, 1,9"), Ok(Seeds(vec![4, 1, 9])));
        assert!(parse_seeds("3-1").unwrap_err().contains("empty"));
        assert!(parse_seeds("1,1").unwrap_err().contains("twice"));
        assert!(parse_seeds("1-5000").unwrap_err().contains("1000"));
        assert!(parse_seeds("a").unwrap_err().contains("range"));
        assert!(parse_condition("L4").is_err());
        assert_eq!(parse_condition("L2"), Ok(Condition::L2));
    }

    fn trial(
        condition: Condition,
        delays: &[Option<f64>],
        assessed: &[(bool, &str)],
    ) -> TrialEpisodes {
        TrialEpisodes {
            seed: 1,
            condition,
            episodes: HesitationEpisodes {
                ground_truth: delays.len() as u64,
                detected: delays.iter().filter(|d| d.is_some()).count() as u64,
                recall: None,
                assessed: assessed.len() as u64,
                matched: assessed.iter().filter(|a| a.0).count() as u64,
                precision: None,
                onset_delay_median_s: None,
                truth_episodes: delays
                    .iter()
                    .map(|&d| TruthEpisode {
                        start_s: 0.0,
                        end_s: 1.0,
                        detected_s: d,
                        delay_s: d,
                        attributed_onset_s: d.map(|x| x - 0.3),
                    })
                    .collect(),
                assessed_episodes: assessed
                    .iter()
                    .map(|&(matched, phase)| AssessedEpisode {
                        start_s: 0.0,
                        detected_s: 0.3,
                        end_s: 1.0,
                        matched,
                        phase: Some(phase.into()),
                    })
                    .collect(),
            },
            share: (None, None),
        }
    }

    /// Pooling is over episodes, not a mean of per-trial ratios; computed by hand below.
    #[test]
    fn pooling_counts_episodes_over_trials_by_hand() {
        // Trial 1 (L1): 3 truth, 2 detected (0.2, 0.6 s); 2 assessed, 1 matched, 1 in Present.
        // Trial 2 (L2): 1 truth, detected (0.4 s); 3 assessed, 3 matched.
        let t = [
            trial(
                Condition::L1,
                &[Some(0.2), None, Some(0.6)],
                &[(true, "Approach"), (false, "Present")],
            ),
            trial(
                Condition::L2,
                &[Some(0.4)],
                &[(true, "Approach"), (true, "Approach"), (true, "Present")],
            ),
        ];
        let p = Pooled::of(&t);
        // recall (2 + 1) / (3 + 1) = 0.75; the mean of per-trial recalls would be 0.833.
        assert_eq!(p.recall(), Some(0.75));
        // precision (1 + 3) / (2 + 3) = 0.8.
        assert_eq!(p.precision(), Some(0.8));
        assert_eq!(p.delays, vec![0.2, 0.4, 0.6]);
        assert_eq!(median(&p.delays), Some(0.4));
        assert_eq!(p.unmatched_by_phase, vec![("Present".to_string(), 1)]);
        let md = markdown(
            &t,
            &[Condition::L1, Condition::L2],
            PolicyKind::Adaptive,
            2,
            0,
        );
        assert!(md.contains("SIMULATED"), "{md}");
        // The all row: 2 trials, 4 truth, 3 detected, 0.750, 5 assessed, 4 matched, 0.800,
        // median 0.4, q25–q75 0.3–0.5 (type 7 over 0.2, 0.4, 0.6).
        assert!(
            md.contains(
                "| all (2) | 4 | 3 | 0.750 | 5 | 4 | 0.800 | 0.400 | 0.300–0.500 | 0.100 |"
            ),
            "{md}"
        );
        assert!(md.contains("- recall ≥ 0.8: **not met**"), "{md}");
        assert!(md.contains("- precision ≥ 0.8: met"), "{md}");
        assert!(md.contains("- median onset delay ≤ 0.5 s: met"), "{md}");
        assert!(md.contains("| Present | 1 |"), "{md}");
    }
}
