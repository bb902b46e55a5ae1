//! End to end: a tiny simulated experiment into a temporary folder.

use super::*;

/// The shipped trial config with absolute paths and trials cut at `max_s` of trial time.
fn short_trial_config(dir: &Path, max_s: f64) -> PathBuf {
    let config_dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("config");
    let mut text = crate::trial::config::SHIPPED_TOML.to_owned();
    for name in [
        "example-workspace.toml",
        "handover.toml",
        "policy-adaptive.toml",
        "assess.toml",
    ] {
        text = text.replace(
            &format!("\"{name}\""),
            &format!("{:?}", config_dir.join(name).display().to_string()),
        );
    }
    let text = text.replace(
        "max_duration_s = 600.0",
        &format!("max_duration_s = {max_s}"),
    );
    assert!(text.contains(&format!("max_duration_s = {max_s}")));
    let path = dir.join("trial-short.toml");
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn tiny_experiment_runs_end_to_end() {
    let tmp = tempfile::tempdir().unwrap();
    short_trial_config(tmp.path(), 20.0);
    let cfg = tmp.path().join("ab.toml");
    std::fs::write(
        &cfg,
        "participants = 2\nconditions = [\"L1\", \"L3\"]\npolicies = [\"adaptive\", \"fixed\"]\n\
         seed = 11\ntrial_config = \"trial-short.toml\"\n",
    )
    .unwrap();
    let dir = tmp.path().join("exp");
    let out = run_experiment(&cfg, &dir, 2, false).unwrap();
    assert_eq!((out.trials, out.failed), (8, 0));

    // schedule.csv: header + 2 participants × 2 conditions × 2 policies.
    let schedule = std::fs::read_to_string(dir.join("schedule.csv")).unwrap();
    assert_eq!(schedule.lines().count(), 1 + 8, "{schedule}");
    assert!(schedule.starts_with("participant,position,condition,policy,square_row,seed,folder"));

    let summary: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.join("experiment_summary.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(summary["simulated"], true);
    assert_eq!(summary["trials"].as_array().unwrap().len(), 8);
    assert_eq!(summary["failures"], 0);
    // 2 policies × 2 conditions, 2 trials each.
    let table = summary["table"].as_array().unwrap();
    assert_eq!(table.len(), 4);
    for row in table {
        assert_eq!(row["metrics"]["completion_time_s"]["n"], 2);
    }
    assert_eq!(
        summary["policy_comparison"]["metrics"]
            .as_array()
            .unwrap()
            .len(),
        aggregate::METRICS.len()
    );
    for p in ["adaptive", "fixed"] {
        assert_eq!(
            summary["friedman_across_conditions"][p]
                .as_array()
                .unwrap()
                .len(),
            aggregate::METRICS.len()
        );
    }

    let html = std::fs::read_to_string(dir.join("experiment_report.html")).unwrap();
    assert_eq!(
        html.matches("src=\"data:image/png;base64,").count(),
        aggregate::METRICS.len()
    );
    assert!(html.contains("SIMULATED"));
    // One trial row per trial in the report's trial table.
    assert_eq!(html.matches("<td>ok</td>").count(), 8);

    // Every trial folder has its summary, and the seeds are those of `trial_seed`.
    let trials = aggregate::read_outcomes(&dir).unwrap();
    assert_eq!(trials.len(), 8);
    let mut rdr = csv::Reader::from_path(dir.join("schedule.csv")).unwrap();
    for rec in rdr.records() {
        let rec = rec.unwrap();
        let p: usize = rec[0][1..].parse::<usize>().unwrap() - 1;
        let pos: usize = rec[1].parse().unwrap();
        assert_eq!(rec[5].parse::<u64>().unwrap(), trial_seed(11, p, pos));
        assert!(dir.join(&rec[6]).join("summary.json").is_file());
    }
}

#[test]
fn a_failing_trial_is_reported_and_the_others_still_run() {
    let tmp = tempfile::tempdir().unwrap();
    let trial_cfg = short_trial_config(tmp.path(), 5.0);
    let config = TrialConfig::from_file(&trial_cfg).unwrap();
    let schedule = ExperimentDesign {
        participants: 2,
        conditions: vec![Condition::L1],
        policies: vec!["adaptive".into(), "fixed".into()],
        seed: 3,
    }
    .schedule()
    .unwrap();
    let sessions = plan(&schedule, 3).unwrap();
    let dir = tmp.path().join("exp");
    std::fs::create_dir(&dir).unwrap();
    // A file where the first trial's folder should go makes that trial fail.
    let blocked = sessions[0][0].folder.clone();
    std::fs::write(dir.join(&blocked), "not a folder").unwrap();
    let mut seen = 0;
    let runs = run_trials(sessions, &config, &dir, 2, &mut |_| seen += 1);
    assert_eq!((runs.len(), seen), (4, 4));
    let failed: Vec<_> = runs.iter().filter(|r| r.error.is_some()).collect();
    assert_eq!(failed.len(), 1, "{runs:?}");
    assert_eq!(failed[0].trial.folder, blocked);
}

#[test]
fn shipped_experiment_config_is_the_acceptance_design() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/experiment-ab.toml");
    let cfg = ExperimentConfig::from_file(&path).unwrap();
    assert_eq!(cfg.participants, 8);
    assert_eq!(cfg.conditions, Condition::ALL.to_vec());
    assert_eq!(cfg.policies, ["adaptive", "fixed"]);
    assert!(TrialConfig::from_file(&cfg.trial_config).is_ok());
    let schedule = cfg.design().schedule().unwrap();
    assert_eq!(schedule.trials().len(), 48);
    // Unknown keys are refused by name.
    let tmp = tempfile::tempdir().unwrap();
    let bad = tmp.path().join("bad.toml");
    std::fs::write(
        &bad,
        std::fs::read_to_string(&path).unwrap() + "\nparticipant = 3\n",
    )
    .unwrap();
    let err = format!("{:#}", ExperimentConfig::from_file(&bad).unwrap_err());
    assert!(err.contains("participant"), "{err}");
}

#[test]
fn trial_seeds_differ_and_are_reproducible() {
    let mut seeds = std::collections::BTreeSet::new();
    for p in 0..8 {
        for pos in 1..=6 {
            assert!(seeds.insert(trial_seed(2026, p, pos)));
        }
    }
    assert_eq!(trial_seed(2026, 3, 4), trial_seed(2026, 3, 4));
    assert_ne!(trial_seed(2026, 3, 4), trial_seed(2027, 3, 4));
}
