//! Aggregation and statistics over a folder of trial folders (each with its `summary.json`):
//! the policy × condition table, the paired policy comparison (Wilcoxon + Holm) and the Friedman
//! test across conditions.
//!
//! # What is read from `summary.json` (the trial log's schema, `src/trial/log_summary.rs`)
//! - `meta.participant`, `meta.condition`, `meta.policy`, `meta.simulated`;
//! - `completion_time_s`, `operator_idle_s`, `robot_idle_s`: numbers;
//! - `hesitation_share`: the **assessed** share (`hesitation_share.assessed`, time with H = 1 over
//!   time with C = 1), not the simulated operator's ground truth, because the assessed share is
//!   what a real experiment can measure; `null` (C never 1) is a missing value;
//! - `hrc_cwl_mean`: the time-weighted mean of the **cumulative** HRC-CWL
//!   (`hrc_cwl_mean.cumulative`); `null` is a missing value;
//! - `robot_wait_s`, `operator_wait_s`: sums over `handovers[]` of the non-`null` waits (a
//!   `null` wait, e.g. a handover never grasped, contributes nothing; a trial without handovers
//!   sums to 0);
//! - `return_rate`: the share of `handovers[]` with `returned` (a part that went back at least
//!   once); NaN for a trial without handovers;
//! - `part_wait_share`: the summed `robot_wait_s` (time a part waited at the handover point)
//!   over `completion_time_s`; NaN for a trial of zero length.
//!
//! Missing values are NaN in [`TrialOutcome::metrics`]; every statistic leaves them out (the
//! table counts only present values, a pair or a Friedman block with a missing value is dropped
//! for that metric).

use std::collections::BTreeMap;

use crate::stats;

/// The per-trial outcomes compared between policies, in this order: the `summary.json` key (or,
/// for the two wait times, the sum over `handovers[]`) and the report label.
pub(crate) const METRICS: [&str; 9] = [
    "completion_time_s",
    "hesitation_share",
    "hrc_cwl_mean",
    "operator_idle_s",
    "robot_idle_s",
    "robot_wait_s",
    "operator_wait_s",
    "return_rate",
    "part_wait_share",
];

/// One trial's `summary.json`, reduced to what the experiment statistics use.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct TrialOutcome {
    /// `meta.participant`.
    pub(crate) participant: String,
    /// `meta.condition` (L1, L2, L3).
    pub(crate) condition: String,
    /// `meta.policy` (e.g. `fixed`, `adaptive`).
    pub(crate) policy: String,
    /// `meta.simulated`: the operator was the simulated one.
    pub(crate) simulated: bool,
    /// The [`METRICS`] values, in that order; the wait times are totals over the trial's
    /// handovers [s]; NaN for a missing value (`null` in the summary).
    pub(crate) metrics: [f64; METRICS.len()],
    /// `adaptation_changes.by_indicator`: how often the policy adopted each rule (its key:
    /// `AED`, …, `none`).
    pub(crate) rules_adopted: BTreeMap<String, u64>,
}

/// Parses one `summary.json` text (the schema of the module docs).
pub(crate) fn parse_summary(text: &str) -> crate::Result<TrialOutcome> {
    use crate::Error;
    let bad = |reason: String| Error::data("summary.json", reason);
    let v: serde_json::Value =
        serde_json::from_str(text).map_err(Error::json("read", "summary.json"))?;
    let meta_str = |key: &str| -> crate::Result<String> {
        v["meta"][key]
            .as_str()
            .map(str::to_owned)
            .ok_or_else(|| bad(format!("meta.{key} missing or not a string")))
    };
    let num = |key: &str| -> crate::Result<f64> {
        v[key]
            .as_f64()
            .ok_or_else(|| bad(format!("{key} missing or not a number")))
    };
    // A number, or NaN for `null`; anything else (absent, a string, an object) is an error.
    let nullable = |outer: &str, inner: &str| -> crate::Result<f64> {
        let x = &v[outer][inner];
        if x.is_null() && v[outer].as_object().is_some_and(|o| o.contains_key(inner)) {
            return Ok(f64::NAN);
        }
        x.as_f64().ok_or_else(|| {
            bad(format!(
                "{outer}.{inner} missing or neither a number nor null"
            ))
        })
    };
    let (participant, condition, policy) = (
        meta_str("participant")?,
        meta_str("condition")?,
        meta_str("policy")?,
    );
    let simulated = v["meta"]["simulated"]
        .as_bool()
        .ok_or_else(|| bad("meta.simulated missing or not a boolean".into()))?;
    let handovers = v["handovers"]
        .as_array()
        .ok_or_else(|| bad("handovers missing or not an array".into()))?;
    let wait_sum = |key: &str| -> crate::Result<f64> {
        handovers.iter().enumerate().try_fold(0.0, |acc, (i, h)| {
            let w = &h[key];
            if w.is_null() && h.as_object().is_some_and(|o| o.contains_key(key)) {
                return Ok(acc);
            }
            w.as_f64().map(|w| acc + w).ok_or_else(|| {
                bad(format!(
                    "handovers[{i}].{key} missing or neither a number nor null"
                ))
            })
        })
    };
    let by_indicator = v["adaptation_changes"]["by_indicator"]
        .as_object()
        .ok_or_else(|| bad("adaptation_changes.by_indicator missing or not an object".into()))?;
    let mut rules_adopted = BTreeMap::new();
    for (key, n) in by_indicator {
        let n = n.as_u64().ok_or_else(|| {
            bad(format!(
                "adaptation_changes.by_indicator.{key} is not a whole number"
            ))
        })?;
        rules_adopted.insert(key.clone(), n);
    }
    let mut returned = 0usize;
    for (i, h) in handovers.iter().enumerate() {
        let r = h["returned"]
            .as_bool()
            .ok_or_else(|| bad(format!("handovers[{i}].returned missing or not a boolean")))?;
        returned += usize::from(r);
    }
    let return_rate = if handovers.is_empty() {
        f64::NAN
    } else {
        returned as f64 / handovers.len() as f64
    };
    let completion = num("completion_time_s")?;
    let robot_wait = wait_sum("robot_wait_s")?;
    let part_wait_share = if completion > 0.0 {
        robot_wait / completion
    } else {
        f64::NAN
    };
    Ok(TrialOutcome {
        participant,
        condition,
        policy,
        simulated,
        metrics: [
            completion,
            nullable("hesitation_share", "assessed")?,
            nullable("hrc_cwl_mean", "cumulative")?,
            num("operator_idle_s")?,
            num("robot_idle_s")?,
            robot_wait,
            wait_sum("operator_wait_s")?,
            return_rate,
            part_wait_share,
        ],
        rules_adopted,
    })
}

/// Per policy and rule key: how often the rule was adopted over all trials, and in how many
/// trials at least once ("how often each rule fired").
pub(crate) fn rules_fired(outcomes: &[TrialOutcome]) -> BTreeMap<(String, String), (u64, usize)> {
    let mut out: BTreeMap<(String, String), (u64, usize)> = BTreeMap::new();
    for o in outcomes {
        for (key, &n) in &o.rules_adopted {
            let e = out.entry((o.policy.clone(), key.clone())).or_default();
            e.0 += n;
            e.1 += usize::from(n > 0);
        }
    }
    out
}

/// Reads `summary.json` from every direct sub-folder of `runs` that has one, sorted by folder
/// name (so the result does not depend on the file system's order).
pub(crate) fn read_outcomes(runs: &std::path::Path) -> crate::Result<Vec<TrialOutcome>> {
    use crate::Error;
    let mut paths = Vec::new();
    for entry in std::fs::read_dir(runs).map_err(Error::io("list", runs))? {
        let path = entry
            .map_err(Error::io("list", runs))?
            .path()
            .join("summary.json");
        if path.is_file() {
            paths.push(path);
        }
    }
    paths.sort();
    paths
        .iter()
        .map(|p| {
            let text = std::fs::read_to_string(p).map_err(Error::io("read", p))?;
            parse_summary(&text).map_err(|e| e.in_file(p))
        })
        .collect()
}

/// The q-quantile of sorted finite `xs` by linear interpolation between order statistics
/// (Hyndman–Fan type 7, R's and numpy's default); NaN when `xs` is empty.
pub(crate) fn quantile(xs: &[f64], q: f64) -> f64 {
    match xs.len() {
        0 => f64::NAN,
        n => {
            let h = (n - 1) as f64 * q;
            let (lo, hi) = (h.floor() as usize, h.ceil() as usize);
            xs[lo] + (h - lo as f64) * (xs[hi] - xs[lo])
        }
    }
}

/// The present (finite) values of metric `m` for one policy × condition cell, sorted.
pub(crate) fn cell_values(
    outcomes: &[TrialOutcome],
    policy: &str,
    condition: &str,
    m: usize,
) -> Vec<f64> {
    let mut xs: Vec<f64> = outcomes
        .iter()
        .filter(|o| o.policy == policy && o.condition == condition)
        .map(|o| o.metrics[m])
        .filter(|x| x.is_finite())
        .collect();
    xs.sort_by(f64::total_cmp);
    xs
}

/// One cell of the policy × condition table: a metric's trials summarised.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Cell {
    /// Number of trials with the value present.
    pub(crate) n: usize,
    /// Mean.
    pub(crate) mean: f64,
    /// Median (mean of the middle two for even n); NaN when n = 0.
    pub(crate) median: f64,
}

/// The policy × condition table of every metric: `table[(policy, condition)][metric index]`.
pub(crate) fn table(
    outcomes: &[TrialOutcome],
) -> BTreeMap<(String, String), [Cell; METRICS.len()]> {
    let mut groups: BTreeMap<(String, String), Vec<&TrialOutcome>> = BTreeMap::new();
    for o in outcomes {
        groups
            .entry((o.policy.clone(), o.condition.clone()))
            .or_default()
            .push(o);
    }
    groups
        .into_iter()
        .map(|(key, trials)| {
            let cells = std::array::from_fn(|m| {
                let mut xs: Vec<f64> = trials
                    .iter()
                    .map(|t| t.metrics[m])
                    .filter(|x| x.is_finite())
                    .collect();
                xs.sort_by(f64::total_cmp);
                let n = xs.len();
                Cell {
                    n,
                    mean: if n == 0 {
                        f64::NAN
                    } else {
                        xs.iter().sum::<f64>() / n as f64
                    },
                    median: quantile(&xs, 0.5),
                }
            });
            (key, cells)
        })
        .collect()
}

/// The paired policy comparison of one metric.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct PolicyTest {
    /// Index into [`METRICS`].
    pub(crate) metric: usize,
    /// The Wilcoxon signed-rank test of `a − b` (zero handling: Wilcox, scipy's default; method
    /// chosen as scipy's `auto`), or why the metric could not be tested (e.g. every difference
    /// zero: the policies do not differ on it).
    pub(crate) wilcoxon: Result<stats::WilcoxonResult, stats::StatsError>,
    /// The Holm-adjusted p-value across the metrics that could be tested.
    pub(crate) p_holm: Option<f64>,
    /// Number of participant pairs (participants with the metric present under both policies).
    pub(crate) n_pairs: usize,
    /// Median over participants of the paired difference `a − b` (an effect size in the
    /// metric's unit; NaN without pairs).
    pub(crate) median_difference: f64,
}

/// Paired comparison of policy `a` against `b` for every metric: each participant contributes
/// one pair, their mean over the conditions they ran under both policies (trials of one
/// participant are not independent, so they are not paired per condition). Wilcoxon
/// signed-rank per metric, Holm across the metrics that could be tested.
pub(crate) fn compare_policies(
    outcomes: &[TrialOutcome],
    a: &str,
    b: &str,
) -> crate::Result<Vec<PolicyTest>> {
    // participant -> condition -> (a, b)
    let mut by_participant: BTreeMap<&str, BTreeMap<&str, [Option<&TrialOutcome>; 2]>> =
        BTreeMap::new();
    for o in outcomes {
        let side = if o.policy == a {
            0
        } else if o.policy == b {
            1
        } else {
            continue;
        };
        let slot = by_participant
            .entry(&o.participant)
            .or_default()
            .entry(&o.condition)
            .or_default();
        ensure!(
            slot[side].is_none(),
            crate::Error::data(
                "the trial outcomes",
                format!(
                    "participant {} ran condition {} with policy {} twice",
                    o.participant, o.condition, o.policy
                )
            )
        );
        slot[side] = Some(o);
    }
    let mut tests = Vec::with_capacity(METRICS.len());
    for m in 0..METRICS.len() {
        let (mut xa, mut xb) = (Vec::new(), Vec::new());
        for conditions in by_participant.values() {
            let pairs: Vec<(f64, f64)> = conditions
                .values()
                .filter_map(|s| Some((s[0]?.metrics[m], s[1]?.metrics[m])))
                .filter(|(x, y)| x.is_finite() && y.is_finite())
                .collect();
            if !pairs.is_empty() {
                let k = pairs.len() as f64;
                xa.push(pairs.iter().map(|p| p.0).sum::<f64>() / k);
                xb.push(pairs.iter().map(|p| p.1).sum::<f64>() / k);
            }
        }
        ensure!(
            by_participant
                .values()
                .any(|c| c.values().any(|s| s[0].is_some() && s[1].is_some())),
            crate::Error::data(
                "the trial outcomes",
                format!("no participant ran both {a} and {b}")
            )
        );
        let wilcoxon = stats::wilcoxon(&xa, &xb, stats::WilcoxonOptions::default());
        let mut d: Vec<f64> = xa.iter().zip(&xb).map(|(x, y)| x - y).collect();
        d.sort_by(f64::total_cmp);
        tests.push(PolicyTest {
            metric: m,
            wilcoxon,
            p_holm: None,
            n_pairs: d.len(),
            median_difference: quantile(&d, 0.5),
        });
    }
    let p: Vec<f64> = tests
        .iter()
        .filter_map(|t| Some(t.wilcoxon.as_ref().ok()?.p_value))
        .collect();
    let mut adjusted = stats::holm(&p)
        .map_err(|e| crate::Error::data("Holm", e.to_string()))?
        .into_iter();
    for t in tests.iter_mut().filter(|t| t.wilcoxon.is_ok()) {
        t.p_holm = adjusted.next();
    }
    Ok(tests)
}

/// Friedman test across conditions of every metric for one policy: blocks are the participants
/// who ran every condition (sorted by name) under it; others are left out. One entry per
/// metric, in [`METRICS`] order, with why it could not be computed (e.g. every block tied). A
/// block with a missing value of a metric is left out of that metric's test. The statistic is
/// tie-corrected (midranks within a block; see [`stats::friedman`]).
pub(crate) fn friedman_across_conditions(
    outcomes: &[TrialOutcome],
    policy: &str,
) -> Vec<Result<stats::FriedmanResult, stats::StatsError>> {
    let conditions: std::collections::BTreeSet<&str> = outcomes
        .iter()
        .filter(|o| o.policy == policy)
        .map(|o| o.condition.as_str())
        .collect();
    let mut rows: BTreeMap<&str, BTreeMap<&str, &TrialOutcome>> = BTreeMap::new();
    for o in outcomes.iter().filter(|o| o.policy == policy) {
        rows.entry(&o.participant)
            .or_default()
            .insert(&o.condition, o);
    }
    let complete: Vec<_> = rows
        .values()
        .filter(|r| r.len() == conditions.len())
        .collect();
    (0..METRICS.len())
        .map(|m| {
            let blocks: Vec<Vec<f64>> = complete
                .iter()
                .map(|r| r.values().map(|o| o.metrics[m]).collect::<Vec<f64>>())
                .filter(|b| b.iter().all(|x| x.is_finite()))
                .collect();
            stats::friedman(&blocks)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hand-made summary.json in the trial log's schema (`src/trial/log_summary.rs`): `meta`,
    /// the nested hesitation and HRC-CWL objects (with decoys in the fields not read), and a
    /// third handover whose waits are `null`.
    fn summary(p: &str, c: &str, policy: &str, t: f64, waits: [f64; 2]) -> String {
        format!(
            r#"{{"meta": {{"participant": "{p}", "condition": "{c}", "policy": "{policy}",
                          "seed": 7, "simulated": true, "robot": "sim"}},
                "completion_time_s": {t}, "finish_reason": "completed",
                "handovers": [
                    {{"index": 1, "robot_wait_s": {rw}, "operator_wait_s": 1.0, "returned": false}},
                    {{"index": 2, "robot_wait_s": 0.5, "operator_wait_s": {ow}, "returned": true}},
                    {{"index": 3, "robot_wait_s": null, "operator_wait_s": null, "returned": false}}],
                "robot_idle_s": 3.0, "operator_idle_s": {oi},
                "hesitation_share": {{"assessed": {h}, "ground_truth": 0.9,
                                      "collaboration_time_s": 40.0}},
                "hrc_cwl_mean": {{"cumulative": {cwl}, "windowed": 0.99}},
                "hrc_cwl_max": {{"cumulative": 0.98, "windowed": 0.97}},
                "dominant_time_s": {{"AED": 1.0, "none": 2.0}},
                "adaptation_changes": {{"total": 3, "by_indicator": {{"OHD": 2, "none": 1}}}},
                "safety_events": {{"total": 0, "by_reaction": {{}}, "by_requirement": {{}}}},
                "assessed_frames": 100}}"#,
            h = t / 1000.0,
            cwl = t / 250.0,
            oi = t / 10.0,
            rw = waits[0],
            ow = waits[1],
        )
    }

    #[test]
    fn parses_the_trial_log_schema_and_sums_handover_waits() {
        let o = parse_summary(&summary("P01", "L2", "adaptive", 100.0, [2.0, 3.0])).unwrap();
        assert_eq!(
            (
                o.participant.as_str(),
                o.condition.as_str(),
                o.policy.as_str(),
                o.simulated
            ),
            ("P01", "L2", "adaptive", true)
        );
        // Assessed share and cumulative mean, not the decoys; the null waits add nothing. By
        // hand: one of the three handovers returned its part (1/3), and the parts waited
        // 2.0 + 0.5 s of the 100 s trial at the handover point (0.025).
        assert_eq!(
            o.metrics,
            [100.0, 0.1, 0.4, 10.0, 3.0, 2.5, 4.0, 1.0 / 3.0, 0.025]
        );
        assert_eq!(
            o.rules_adopted,
            BTreeMap::from([("OHD".to_owned(), 2), ("none".to_owned(), 1)])
        );
        // Over two trials of each policy: adoptions summed, trials with one counted.
        let mut two = vec![o.clone(), o.clone()];
        two[1].rules_adopted.insert("OHD".to_owned(), 0);
        let fired = rules_fired(&two);
        assert_eq!(fired[&("adaptive".to_owned(), "OHD".to_owned())], (2, 1));
        assert_eq!(fired[&("adaptive".to_owned(), "none".to_owned())], (2, 2));
        // No handover: no return rate (a missing value); the waits sum to 0.
        let text = summary("P01", "L2", "adaptive", 100.0, [2.0, 3.0]);
        let start = text.find(r#""handovers": ["#).unwrap();
        let end = text[start..].find("]").unwrap() + start + 1;
        let none = format!("{}\"handovers\": []{}", &text[..start], &text[end..]);
        let o = parse_summary(&none).unwrap();
        assert!(o.metrics[7].is_nan(), "{:?}", o.metrics);
        assert_eq!((o.metrics[5], o.metrics[8]), (0.0, 0.0));
        // `returned` must be a boolean.
        let bad = summary("P01", "L2", "adaptive", 100.0, [2.0, 3.0]).replacen(
            r#""returned": false"#,
            r#""returned": 0"#,
            1,
        );
        let err = parse_summary(&bad).unwrap_err();
        assert!(err.to_string().contains("handovers[0].returned"), "{err}");

        // `null` share and mean (C never 1, no frames) are missing values, not errors.
        let text = summary("P01", "L2", "adaptive", 100.0, [2.0, 3.0])
            .replace(r#""assessed": 0.1"#, r#""assessed": null"#)
            .replace(r#""cumulative": 0.4"#, r#""cumulative": null"#);
        let o = parse_summary(&text).unwrap();
        assert!(o.metrics[1].is_nan() && o.metrics[2].is_nan());
        assert_eq!(o.metrics[0], 100.0);

        // The interim flat schema (a number where the object belongs) is rejected by name.
        let flat = summary("P01", "L2", "adaptive", 100.0, [2.0, 3.0])
            .replace(r#"{"cumulative": 0.4, "windowed": 0.99}"#, "0.4");
        let err = parse_summary(&flat).unwrap_err();
        assert!(err.to_string().contains("hrc_cwl_mean.cumulative"), "{err}");
        let err =
            parse_summary(r#"{"meta": {"participant": "P", "condition": "L1"}}"#).unwrap_err();
        assert!(err.to_string().contains("meta.policy"), "{err}");
    }

    #[test]
    fn missing_values_are_left_out_of_table_pairs_and_blocks() {
        let mut outcomes = Vec::new();
        for i in 0..4 {
            for (ci, c) in ["L1", "L2"].into_iter().enumerate() {
                let base = 100.0 + i as f64 + 5.0 * ci as f64;
                for (policy, t) in [("fixed", base), ("adaptive", base - 10.0)] {
                    let mut text = summary(&format!("P{i}"), c, policy, t, [1.0, 1.0]);
                    if i == 0 && policy == "fixed" {
                        text = text.replace(
                            &format!(r#""assessed": {}"#, t / 1000.0),
                            r#""assessed": null"#,
                        );
                    }
                    outcomes.push(parse_summary(&text).unwrap());
                }
            }
        }
        let tab = table(&outcomes);
        assert_eq!(tab[&("fixed".to_owned(), "L1".to_owned())][1].n, 3);
        assert_eq!(tab[&("fixed".to_owned(), "L1".to_owned())][0].n, 4);
        let tests = compare_policies(&outcomes, "adaptive", "fixed").unwrap();
        assert_eq!((tests[0].n_pairs, tests[1].n_pairs), (4, 3));
        assert_eq!(tests[0].median_difference, -10.0);
        let fr = friedman_across_conditions(&outcomes, "fixed");
        assert_eq!(fr[0].as_ref().unwrap().n, 4);
        assert_eq!(fr[1].as_ref().unwrap().n, 3);
    }

    #[test]
    fn reads_folders_aggregates_and_tests() {
        let dir = tempfile::tempdir().unwrap();
        // 8 participants × 3 conditions × 2 policies; adaptive is faster by 5 + i s.
        for i in 0..8 {
            for (ci, c) in ["L1", "L2", "L3"].iter().enumerate() {
                for policy in ["fixed", "adaptive"] {
                    let base = 100.0 + 10.0 * ci as f64 + i as f64;
                    let t = if policy == "adaptive" {
                        base - 5.0 - i as f64
                    } else {
                        base
                    };
                    let folder = dir.path().join(format!("run-P{i}-{c}-{policy}"));
                    std::fs::create_dir(&folder).unwrap();
                    std::fs::write(
                        folder.join("summary.json"),
                        summary(&format!("P{i}"), c, policy, t, [1.0, 1.0]),
                    )
                    .unwrap();
                }
            }
        }
        std::fs::create_dir(dir.path().join("not-a-trial")).unwrap();
        let outcomes = read_outcomes(dir.path()).unwrap();
        assert_eq!(outcomes.len(), 48);

        let tab = table(&outcomes);
        assert_eq!(tab.len(), 6);
        let cell = tab[&("fixed".to_owned(), "L2".to_owned())][0];
        // fixed L2 completion times 110..=117: mean = median = 113.5.
        assert_eq!((cell.n, cell.mean, cell.median), (8, 113.5, 113.5));

        let tests = compare_policies(&outcomes, "adaptive", "fixed").unwrap();
        assert_eq!(tests.len(), METRICS.len());
        // Completion time: all 8 differences negative and distinct → exact p = 2/256.
        let ct = tests[0].wilcoxon.as_ref().unwrap();
        assert_eq!(
            (ct.r_plus, ct.r_minus, ct.p_value),
            (0.0, 36.0, 2.0 / 256.0)
        );
        assert_eq!(ct.rank_biserial, -1.0);
        assert_eq!(tests[0].n_pairs, 8);
        // Differences −5 − i, i = 0..8: median −8.5.
        assert_eq!(tests[0].median_difference, -8.5);
        // Robot idle, both wait totals and the return rate (1/3 in every trial) are equal
        // under both policies: not testable, and left out of the Holm family, which is the 5
        // metrics that scale with completion time, the part-wait share (the same wait over a
        // shorter trial) among them (all p = 2/256 → Holm 5·p).
        let testable = [true, true, true, true, false, false, false, false, true];
        assert_eq!(testable.len(), tests.len());
        for (t, testable) in tests.iter().zip(testable) {
            assert_eq!(t.wilcoxon.is_ok(), testable, "{}", METRICS[t.metric]);
            match t.p_holm {
                Some(q) => assert!((q - 5.0 * 2.0 / 256.0).abs() < 1e-15),
                None => assert!(!testable),
            }
        }
        // Friedman across L1–L3 under `fixed`: completion time ranks 1, 2, 3 in every block →
        // χ² = n(k − 1) = 16, W = 1, p = e^−8; the constant robot idle time is all ties.
        let fr = friedman_across_conditions(&outcomes, "fixed");
        let ct = fr[0].as_ref().unwrap();
        assert_eq!((ct.n, ct.k, ct.statistic, ct.kendall_w), (8, 3, 16.0, 1.0));
        assert!((ct.p_value - (-8.0_f64).exp()).abs() < 1e-15);
        assert!(fr[4].is_err());
    }
}
