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

/// Writes `dir/ab.toml`: a tiny A/B experiment of `participants` participants over
/// `conditions` (e.g. `"\"L1\", \"L3\""`), adaptive against fixed, with `seed`, on
/// `trial-short.toml` (see [`short_trial_config`]). Returns its path.
fn tiny_experiment_config(dir: &Path, participants: usize, conditions: &str, seed: u64) -> PathBuf {
    let cfg = dir.join("ab.toml");
    std::fs::write(
        &cfg,
        format!(
            "participants = {participants}\nconditions = [{conditions}]\n\
             policies = [\"adaptive\", \"fixed\"]\nseed = {seed}\n\
             trial_config = \"trial-short.toml\"\n"
        ),
    )
    .unwrap();
    cfg
}

#[test]
fn tiny_experiment_runs_end_to_end() {
    let tmp = tempfile::tempdir().unwrap();
    short_trial_config(tmp.path(), 20.0);
    let cfg = tiny_experiment_config(tmp.path(), 2, "\"L1\", \"L3\"", 11);
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
fn an_experiment_whose_trials_failed_exits_non_zero_after_writing_its_report() {
    // At a077dd5 `experiment` exited 0 when every trial failed. Here every trial fails at
    // once: the trial config names a workspace file that does not exist.
    let tmp = tempfile::tempdir().unwrap();
    let trial_cfg = short_trial_config(tmp.path(), 2.0);
    let text = std::fs::read_to_string(&trial_cfg).unwrap();
    let workspace = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/example-workspace.toml");
    let text = text.replace(
        &format!("{:?}", workspace.display().to_string()),
        "\"missing-workspace.toml\"",
    );
    assert!(text.contains("missing-workspace.toml"));
    std::fs::write(&trial_cfg, text).unwrap();
    let cfg = tiny_experiment_config(tmp.path(), 1, "\"L1\"", 1);
    #[derive(clap::Parser)]
    struct Cli {
        #[command(flatten)]
        args: ExperimentArgs,
    }
    let root = tmp.path().join("runs");
    let args = <Cli as clap::Parser>::try_parse_from([
        "experiment".as_ref(),
        "--config".as_ref(),
        cfg.as_os_str(),
        "--out-root".as_ref(),
        root.as_os_str(),
        "--jobs".as_ref(),
        "1".as_ref(),
    ] as [&std::ffi::OsStr; 7])
    .unwrap()
    .args;
    let e = run(args).unwrap_err().with_causes().to_string();
    assert!(e.contains("2 of 2 trials failed"), "{e}");
    // Everything that could be written was, and the message says where.
    let dirs: Vec<_> = std::fs::read_dir(&root).unwrap().collect();
    assert_eq!(dirs.len(), 1);
    let dir = dirs[0].as_ref().unwrap().path();
    assert!(e.contains(&dir.display().to_string()), "{e}");
    for f in [
        "schedule.csv",
        "experiment_summary.json",
        "experiment_report.html",
    ] {
        assert!(dir.join(f).is_file(), "{f}");
    }
    let summary = std::fs::read_to_string(dir.join("experiment_summary.json")).unwrap();
    assert!(summary.contains("missing-workspace.toml"), "{summary}");
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
    let err = ExperimentConfig::from_file(&bad)
        .unwrap_err()
        .with_causes()
        .to_string();
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

/// A participant's six planned trials (3 conditions × 2 policies).
fn six_trials() -> Vec<PlannedTrial> {
    let schedule = ExperimentDesign {
        participants: 2,
        conditions: Condition::ALL.to_vec(),
        policies: vec!["adaptive".into(), "fixed".into()],
        seed: 5,
    }
    .schedule()
    .unwrap();
    plan(&schedule, 5).unwrap().remove(1)
}

#[test]
fn guided_session_follows_the_script_and_appends_the_ratings() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let trials = six_trials();
    assert_eq!(trials.len(), 6);
    let script = concat!(
        // Trial 1: start; physical demand is asked again after "25" and "abc".
        "start\n", "10\n", "25\n", "abc\n", "5\n", "15\n", "20\n", "0\n", "10\n",
        // Trial 2: an unknown answer, a pause (Enter resumes), then skip.
        "bogus\n", "pause\n", "\n", "skip\n",
        // Trial 3: start, but the runner fails: no ratings.
        "start\n", // Trial 4: start and six ratings.
        "START\n", "1\n", "2\n", "3\n", "4\n", "5\n", "6\n", // Trial 5: quit.
        "quit\n",
    );
    let mut input = std::io::Cursor::new(script.as_bytes());
    let mut out = Vec::new();
    let mut ran = Vec::new();
    let record = session::run_session(&trials, dir, &mut input, &mut out, &mut |t, folder| {
        ran.push(t.position);
        assert_eq!(folder, dir.join(&t.folder));
        ensure!(
            t.position != 3,
            crate::Error::usage("--robot", "robot not in remote control")
        );
        Ok(folder.to_path_buf())
    })
    .unwrap();
    let out = String::from_utf8(out).unwrap();
    assert_eq!(ran, [1, 3, 4], "{out}");
    assert!(record.quit);
    use session::StepOutcome as S;
    let outcomes: Vec<_> = record.steps.iter().map(|(_, o)| o.clone()).collect();
    assert_eq!(
        outcomes,
        [
            S::Done { raw_tlx: 10.0 },
            S::Skipped,
            S::Failed("robot not in remote control".into()),
            S::Done { raw_tlx: 3.5 },
        ]
    );
    assert_eq!(record.steps[1].0, trials[1].folder);
    assert!(out.contains(&format!(
        "Next: trial 1 of 6 for P02: condition {}, policy {}",
        trials[0].condition, trials[0].policy
    )));
    assert!(out.contains("trial 5 of 6"), "{out}");
    assert!(!out.contains("trial 6 of 6"), "{out}");
    assert_eq!(out.matches("is not a rating").count(), 2, "{out}");
    // Three times in trial 1 (two bad answers), once in trial 4.
    assert_eq!(out.matches("Physical demand (0-20)").count(), 4, "{out}");
    assert!(out.contains("unknown answer \"bogus\""), "{out}");
    assert!(out.contains("paused; press Enter"), "{out}");
    assert!(out.contains("trial 3 of 6 failed: robot not in remote control"));
    assert!(
        out.contains("2 done, 1 failed, 1 skipped, 2 not reached"),
        "{out}"
    );

    let csv_path = dir.join(session::TLX_FILE);
    let text = std::fs::read_to_string(&csv_path).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(
        lines[0],
        "participant,trial,condition,policy,mental,physical,temporal,performance,effort,\
         frustration,raw_tlx"
    );
    let row = |t: &PlannedTrial, ratings: &str, raw: &str| {
        format!(
            "P02,{},{},{},{ratings},{raw}",
            t.position, t.condition, t.policy
        )
    };
    assert_eq!(lines[1], row(&trials[0], "10,5,15,20,0,10", "10.0000"));
    assert_eq!(lines[2], row(&trials[3], "1,2,3,4,5,6", "3.5000"));
    assert_eq!(lines.len(), 3);

    // Resuming later appends to the same file, without a second header; input ending in the
    // middle of the ratings writes nothing for that trial.
    let mut input = std::io::Cursor::new(&b"start\n7.5\n7.5\n7.5\n7.5\n7.5\n7.5\nstart\n1\n"[..]);
    let mut out = Vec::new();
    let record = session::run_session(&trials[4..], dir, &mut input, &mut out, &mut |_, f| {
        Ok(f.to_path_buf())
    })
    .unwrap();
    assert!(record.quit);
    assert_eq!(record.steps.len(), 1);
    let text = std::fs::read_to_string(&csv_path).unwrap();
    assert_eq!(text.lines().count(), 4, "{text}");
    assert_eq!(text.matches("participant,").count(), 1);
    assert!(text.ends_with(&format!(
        "{}\n",
        row(&trials[4], "7.5,7.5,7.5,7.5,7.5,7.5", "7.5000")
    )));
}

#[test]
fn ctrl_c_at_a_session_prompt_ends_the_session_and_runs_nothing() {
    // At a077dd5 the session read stdin directly: a Ctrl-C (which only sets the flag) was
    // ignored at its prompts. Here the answers never come and the flag is set.
    struct Never;
    impl std::io::Read for Never {
        fn read(&mut self, _: &mut [u8]) -> std::io::Result<usize> {
            loop {
                std::thread::park();
            }
        }
    }
    let tmp = tempfile::tempdir().unwrap();
    let trials = six_trials();
    let stop = std::sync::atomic::AtomicBool::new(true);
    let mut input = crate::trial::prompt::PromptInput::spawn(std::io::BufReader::new(Never), &stop);
    let mut out = Vec::new();
    let mut ran = 0;
    let e = session::run_session(&trials, tmp.path(), &mut input, &mut out, &mut |_, f| {
        ran += 1;
        Ok(f.to_path_buf())
    })
    .unwrap_err();
    assert!(crate::trial::prompt::is_interrupted(&e), "{e:#}");
    assert!(e.with_causes().to_string().contains("interrupted"), "{e:#}");
    assert_eq!(ran, 0);
    assert!(!tmp.path().join(session::TLX_FILE).exists());
    // Also at the ratings: the trial ran, then the flag was set (Ctrl-C at the TLX prompt).
    let stop = std::sync::atomic::AtomicBool::new(false);
    let mut input = crate::trial::prompt::PromptInput::spawn(
        std::io::Read::chain(
            std::io::Cursor::new("start\n5\n"),
            std::io::BufReader::new(Never),
        ),
        &stop,
    );
    let e = session::run_session(&trials, tmp.path(), &mut input, &mut out, &mut |_, f| {
        stop.store(true, std::sync::atomic::Ordering::Relaxed);
        Ok(f.to_path_buf())
    })
    .unwrap_err();
    assert!(crate::trial::prompt::is_interrupted(&e), "{e:#}");
    assert!(!tmp.path().join(session::TLX_FILE).exists());
}

#[test]
fn a_real_session_runs_the_participants_schedule_rows() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/experiment-ab.toml");
    let cfg = ExperimentConfig::from_file(&path).unwrap();
    let trials = participant_trials(&cfg, "P03").unwrap();
    let schedule = plan(&cfg.design().schedule().unwrap(), cfg.seed).unwrap();
    assert_eq!(trials.len(), 6);
    assert_eq!(
        trials.iter().map(|t| &t.folder).collect::<Vec<_>>(),
        schedule[2].iter().map(|t| &t.folder).collect::<Vec<_>>()
    );
    let err = participant_trials(&cfg, "P09")
        .unwrap_err()
        .with_causes()
        .to_string();
    assert!(err.contains("P09 is not in the schedule"), "{err}");
}

/// `--replicate 2` on a tiny experiment: two whole experiments (replication 1 with the file's
/// seed, replication 2 with another), then the power table, whose figures are recomputed here
/// from `replications.csv` (the per-replication p-values) and from each replication's own
/// `experiment_summary.json`.
#[test]
fn two_replications_write_every_experiment_and_a_consistent_power_table() {
    let tmp = tempfile::tempdir().unwrap();
    short_trial_config(tmp.path(), 15.0);
    let cfg = tiny_experiment_config(tmp.path(), 2, "\"L1\"", 11);
    let out = replicate::run_replications(&cfg, &tmp.path().join("rep"), 2, 2, false).unwrap();
    assert_eq!((out.trials, out.failed), (8, 0));
    let summary = |r: usize| -> serde_json::Value {
        let p = out
            .dir
            .join(format!("rep-{r:02}"))
            .join("experiment_summary.json");
        serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
    };
    assert_eq!(summary(1)["design"]["seed"], 11);
    assert_eq!(
        summary(2)["design"]["seed"],
        replicate::replication_seed(11, 2)
    );
    assert_ne!(replicate::replication_seed(11, 2), 11);

    let reps = std::fs::read_to_string(out.dir.join("replications.csv")).unwrap();
    let rows: Vec<Vec<&str>> = reps
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect())
        .collect();
    assert_eq!(rows.len(), 2 * aggregate::METRICS.len(), "{reps}");
    for row in &rows {
        // Each row's p-value is the one its replication's summary reports.
        let r: usize = row[0].parse().unwrap();
        let m = summary(r)["policy_comparison"]["metrics"]
            .as_array()
            .unwrap()
            .iter()
            .find(|m| m["metric"] == row[2])
            .cloned()
            .unwrap();
        match m["p_value"].as_f64() {
            Some(p) => assert_eq!(row[6].parse::<f64>().unwrap(), p, "{row:?}"),
            None => assert_eq!(row[6], "", "{row:?}"),
        }
    }
    let power = std::fs::read_to_string(out.dir.join("power.csv")).unwrap();
    assert_eq!(
        power.lines().count(),
        1 + aggregate::METRICS.len(),
        "{power}"
    );
    for t in &out.table {
        let significant = rows
            .iter()
            .filter(|r| r[2] == t.metric)
            .filter(|r| r[6].parse::<f64>().is_ok_and(|p| p < replicate::ALPHA))
            .count();
        assert_eq!(t.replications, 2);
        assert_eq!(t.power_raw, significant as f64 / 2.0, "{t:?}");
    }
    let md = std::fs::read_to_string(out.dir.join("power.md")).unwrap();
    assert!(md.contains("SIMULATED"), "{md}");
}

/// `--sensitivity` with two variants on a tiny experiment (2 participants, L1, trials cut at
/// 15 s, so 8 short trials): one whole experiment per variant in its own folder, each recording
/// the response it ran with, and `sensitivity.csv`, whose every row is recomputed here from that
/// variant's own files: its `experiment_summary.json` (the experiment's report) and its trial
/// folders' `summary.json` (through the aggregation).
#[test]
fn two_sensitivity_variants_write_every_experiment_and_a_table_recomputed_from_their_files() {
    let tmp = tempfile::tempdir().unwrap();
    short_trial_config(tmp.path(), 15.0);
    let cfg = tiny_experiment_config(tmp.path(), 2, "\"L1\"", 11);
    let file = tmp.path().join("sens.toml");
    std::fs::write(
        &file,
        "[[variant]]\nname = \"none\"\nk_speed = 0.0\nk_acc = 0.0\nsurprise_p = 0.0\n\
         [[variant]]\nname = \"shipped\"\n",
    )
    .unwrap();
    let out =
        sensitivity::run_sensitivity(&cfg, &file, &tmp.path().join("sens"), 2, false).unwrap();
    assert_eq!((out.trials, out.failed), (8, 0));
    assert_eq!(out.variants.len(), 2);
    let shipped = OperatorResponse::default();
    let none = OperatorResponse {
        k_speed: 0.0,
        k_acc: 0.0,
        surprise_p: 0.0,
        ..shipped
    };
    assert_eq!(
        std::fs::read_to_string(out.dir.join("sensitivity.toml")).unwrap(),
        std::fs::read_to_string(&file).unwrap()
    );
    for (v, want) in out.variants.iter().zip([none, shipped]) {
        let vdir = out.dir.join(&v.name);
        // The response it ran with, recorded.
        let text = std::fs::read_to_string(vdir.join(sensitivity::RESPONSE_FILE)).unwrap();
        let recorded: OperatorResponse = toml::from_str(&text).unwrap();
        assert_eq!((recorded, v.response), (want, want), "{}", v.name);
        // A whole experiment: schedule, 4 trials, report.
        assert_eq!(aggregate::read_outcomes(&vdir).unwrap().len(), 4);
        assert!(vdir.join("experiment_report.html").is_file());
    }
    let csv = std::fs::read_to_string(out.dir.join("sensitivity.csv")).unwrap();
    let rows: Vec<Vec<&str>> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect())
        .collect();
    assert_eq!(rows.len(), 2 * aggregate::METRICS.len(), "{csv}");
    // A CSV cell against a value: both empty/absent, or equal to 1e-12 (JSON may round a ULP).
    let same = |cell: &str, x: Option<f64>| match x.filter(|x| x.is_finite()) {
        None => cell.is_empty(),
        Some(x) => cell
            .parse::<f64>()
            .is_ok_and(|c| (c - x).abs() <= 1e-12 * x.abs().max(1.0)),
    };
    for row in &rows {
        let vdir = out.dir.join(row[0]);
        let summary: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(vdir.join("experiment_summary.json")).unwrap(),
        )
        .unwrap();
        let m = summary["policy_comparison"]["metrics"]
            .as_array()
            .unwrap()
            .iter()
            .find(|m| m["metric"] == row[1])
            .cloned()
            .unwrap();
        assert_eq!(row[2], m["n_pairs"].to_string(), "{row:?}");
        for (i, key) in [
            (3, "median_difference"),
            (4, "rank_biserial"),
            (5, "p_value"),
            (6, "p_holm"),
        ] {
            assert!(same(row[i], m[key].as_f64()), "{key}: {row:?} {m}");
        }
        // And from the trial summaries themselves.
        let outcomes = aggregate::read_outcomes(&vdir).unwrap();
        let tests = aggregate::compare_policies(&outcomes, "adaptive", "fixed").unwrap();
        let t = tests
            .iter()
            .find(|t| aggregate::METRICS[t.metric] == row[1])
            .unwrap();
        assert_eq!(row[2], t.n_pairs.to_string(), "{row:?}");
        assert!(same(row[3], Some(t.median_difference)), "{row:?}");
        let w = t.wilcoxon.as_ref().ok();
        assert!(same(row[4], w.map(|w| w.rank_biserial)), "{row:?}");
        assert!(same(row[5], w.map(|w| w.p_value)), "{row:?}");
        assert!(same(row[6], t.p_holm), "{row:?}");
    }
    let md = std::fs::read_to_string(out.dir.join("sensitivity.md")).unwrap();
    assert!(md.contains("SIMULATED"), "{md}");
    assert_eq!(md.matches("| completion_time_s |").count(), 2, "{md}");
}

/// `--sensitivity` with `--replicate` or `--participant` is a usage error naming both.
#[test]
fn sensitivity_excludes_replicate_and_participant() {
    use clap::Parser;
    #[derive(Debug, clap::Parser)]
    struct Cli {
        #[command(flatten)]
        args: ExperimentArgs,
    }
    let base = ["x", "--config", "ab.toml", "--sensitivity", "s.toml"];
    let ok = Cli::try_parse_from(base).unwrap();
    assert_eq!(ok.args.sensitivity, Some(PathBuf::from("s.toml")));
    for extra in [["--replicate", "3"], ["--participant", "P01"]] {
        let e = Cli::try_parse_from(base.iter().chain(&extra)).unwrap_err();
        let text = e.to_string();
        assert_eq!(e.kind(), clap::error::ErrorKind::ArgumentConflict, "{text}");
        assert!(
            text.contains("--sensitivity") && text.contains(extra[0]),
            "{text}"
        );
    }
}
