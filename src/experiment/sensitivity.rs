//! `hrc-adapt experiment --sensitivity <file.toml>`: how the A/B result depends on the
//! simulated operator's response to the robot (issue 14, point 4).
//!
//! The simulated operator's response (more hesitation when the approach is fast or jerky, or
//! when a part arrives while its attention is elsewhere) is an **assumption**, in the trial
//! config's `[operator.response]` ([`OperatorResponse`]). The sensitivity file
//! (`config/sensitivity.toml`) lists named variants of those effect sizes; each variant starts
//! from the trial config's values and replaces the keys it gives. For each variant, in file
//! order, the whole **simulated** experiment of the experiment file runs (same seed, so the
//! same schedule and operator seeds: only the response differs) into its own folder
//! `<variant>/` (every trial folder and report kept, plus `operator_response.toml`, the values
//! it ran with). Then, per variant × metric (`aggregate::METRICS`), the policy comparison
//! `policies[0]` − `policies[1]`: the median paired difference, the rank-biserial r, the
//! Wilcoxon p and the Holm p (across the metrics, within the variant).
//!
//! Written to `<stamp>-sensitivity/`: a copy of the sensitivity file (`sensitivity.toml`),
//! one folder per variant, `sensitivity.csv` (one row per variant × metric) and
//! `sensitivity.md` (labelled SIMULATED).

use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::aggregate::{self, METRICS, TrialOutcome};
use super::replicate::Effect;
use crate::Error;
use crate::trial::config::{OperatorResponse, TrialConfig};

/// The sensitivity file as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFile {
    /// `[[variant]]` tables.
    #[serde(default)]
    variant: Vec<RawVariant>,
}

/// One `[[variant]]`: a name and the response keys it replaces (see [`OperatorResponse`] for
/// their units and ranges).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawVariant {
    name: String,
    ref_speed_m_s: Option<f64>,
    ref_acc_m_s2: Option<f64>,
    k_speed: Option<f64>,
    k_acc: Option<f64>,
    k_duration: Option<f64>,
    surprise_p: Option<f64>,
    surprise_stress: Option<f64>,
}

/// One variant of the response effect sizes.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Variant {
    /// Its name (`[A-Za-z0-9_-]{1,32}`, unique in the file: it names the variant's folder).
    pub(crate) name: String,
    /// The response it runs with: the base (trial config) with its keys replaced.
    pub(crate) response: OperatorResponse,
}

/// Parses a sensitivity file's `text`; each variant starts from `base` (the trial config's
/// `[operator.response]`). Refuses unknown keys, an empty variant list, a bad or duplicate
/// name and an out-of-range value (naming the variant and the key).
pub(crate) fn parse_variants(text: &str, base: OperatorResponse) -> crate::Result<Vec<Variant>> {
    let raw: RawFile = toml::from_str(text).map_err(Error::toml("the sensitivity file"))?;
    ensure!(
        !raw.variant.is_empty(),
        Error::config(
            "variant",
            "lists no variant: add at least one [[variant]] table with a `name`"
        )
    );
    let mut out: Vec<Variant> = Vec::with_capacity(raw.variant.len());
    for (i, v) in raw.variant.into_iter().enumerate() {
        let field = format!("variant[{i}].name");
        crate::trial::participant_id(&v.name).map_err(|_| {
            Error::config(
                field.clone(),
                format!(
                    "must be 1 to 32 letters, digits, `_` or `-` (it names the variant's \
                     folder), got {:?}",
                    v.name
                ),
            )
        })?;
        ensure!(
            out.iter().all(|o| o.name != v.name),
            Error::config(field, format!("{:?} names two variants", v.name))
        );
        let mut r = base;
        for (slot, value) in [
            (&mut r.ref_speed_m_s, v.ref_speed_m_s),
            (&mut r.ref_acc_m_s2, v.ref_acc_m_s2),
            (&mut r.k_speed, v.k_speed),
            (&mut r.k_acc, v.k_acc),
            (&mut r.k_duration, v.k_duration),
            (&mut r.surprise_p, v.surprise_p),
            (&mut r.surprise_stress, v.surprise_stress),
        ] {
            if let Some(value) = value {
                *slot = value;
            }
        }
        r.validate(&format!("variant {:?}: ", v.name))?;
        out.push(Variant {
            name: v.name,
            response: r,
        });
    }
    Ok(out)
}

/// Reads the sensitivity file `path` ([`parse_variants`]); errors name the file.
pub(crate) fn read_variants(path: &Path, base: OperatorResponse) -> crate::Result<Vec<Variant>> {
    let text = std::fs::read_to_string(path).map_err(Error::io("read", path))?;
    parse_variants(&text, base).map_err(|e| e.in_file(path))
}

/// One row of the sensitivity table: a variant's figures for one metric.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct SensitivityRow {
    /// The variant's name.
    pub(crate) variant: String,
    /// The metric (`aggregate::METRICS`).
    pub(crate) metric: &'static str,
    /// The policy comparison's figures (NaN where not tested).
    pub(crate) effect: Effect,
}

/// The sensitivity table: for each `(variant, its trial outcomes)`, in order, the comparison
/// of policy `a` against `b` ([`aggregate::compare_policies`]) per metric, in [`METRICS`]
/// order.
pub(crate) fn sensitivity_table(
    variants: &[(String, Vec<TrialOutcome>)],
    a: &str,
    b: &str,
) -> crate::Result<Vec<SensitivityRow>> {
    let mut rows = Vec::with_capacity(variants.len() * METRICS.len());
    for (name, outcomes) in variants {
        let tests = aggregate::compare_policies(outcomes, a, b)
            .map_err(|e| e.context(format!("variant {name:?}")))?;
        let mut effects = [Effect {
            n_pairs: 0,
            median_difference: f64::NAN,
            rank_biserial: f64::NAN,
            p_value: f64::NAN,
            p_holm: f64::NAN,
        }; METRICS.len()];
        for t in &tests {
            effects[t.metric] = Effect::of(t);
        }
        rows.extend(
            METRICS
                .iter()
                .zip(effects)
                .map(|(&metric, effect)| SensitivityRow {
                    variant: name.clone(),
                    metric,
                    effect,
                }),
        );
    }
    Ok(rows)
}

/// A number for a CSV cell: empty when not finite.
fn cell(x: f64) -> String {
    if x.is_finite() {
        format!("{x}")
    } else {
        String::new()
    }
}

/// Writes `sensitivity.csv` and `sensitivity.md` into `dir`.
pub(crate) fn write(
    dir: &Path,
    policies: [&str; 2],
    variants: &[Variant],
    rows: &[SensitivityRow],
) -> crate::Result<()> {
    let mut csv =
        String::from("variant,metric,n_pairs,median_difference,rank_biserial,p_value,p_holm\n");
    for r in rows {
        let e = r.effect;
        csv.push_str(&format!(
            "{},{},{},{},{},{},{}\n",
            r.variant,
            r.metric,
            e.n_pairs,
            cell(e.median_difference),
            cell(e.rank_biserial),
            cell(e.p_value),
            cell(e.p_holm)
        ));
    }
    let path = dir.join("sensitivity.csv");
    std::fs::write(&path, csv).map_err(Error::io("write", &path))?;

    let [a, b] = policies;
    let mut md = format!(
        "# SIMULATED sensitivity of the A/B result to the operator's response: {a} − {b}\n\n\
         **SIMULATED.** The whole experiment with the simulated operator, once per variant of \
         its response to the robot (`[operator.response]`, every value an assumption: \
         src/trial/config.rs, `OperatorResponse`); same seed, so only the response differs. \
         Effect: the median over participants of the paired difference {a} − {b} (per \
         participant the mean over conditions); r: matched-pairs rank-biserial; p: Wilcoxon \
         signed-rank; Holm: across the metrics within the variant. –: not tested (e.g. no \
         difference).\n\n## Variants\n\n| variant |"
    );
    let names = OperatorResponse::default().fields().map(|(k, _)| k);
    for k in names {
        md.push_str(&format!(" {k} |"));
    }
    md.push_str("\n|---|");
    md.push_str(&"---|".repeat(names.len()));
    md.push('\n');
    for v in variants {
        md.push_str(&format!("| {} |", v.name));
        for (_, x) in v.response.fields() {
            md.push_str(&format!(" {x} |"));
        }
        md.push('\n');
    }
    md.push_str(
        "\n## Policy effect per metric and variant\n\n\
         | metric | variant | pairs | median difference | r | p | Holm p |\n\
         |---|---|---|---|---|---|---|\n",
    );
    let f = |x: f64| {
        if x.is_finite() {
            format!("{x:.3}")
        } else {
            "–".into()
        }
    };
    for metric in METRICS {
        for r in rows.iter().filter(|r| r.metric == metric) {
            let e = r.effect;
            md.push_str(&format!(
                "| {metric} | {} | {} | {} | {} | {} | {} |\n",
                r.variant,
                e.n_pairs,
                f(e.median_difference),
                f(e.rank_biserial),
                f(e.p_value),
                f(e.p_holm)
            ));
        }
    }
    let path = dir.join("sensitivity.md");
    std::fs::write(&path, md).map_err(Error::io("write", &path))?;
    Ok(())
}

/// What [`run_sensitivity`] did.
#[derive(Debug)]
pub(crate) struct SensitivityOutcome {
    /// The folder holding every variant's experiment and the table.
    pub(crate) dir: PathBuf,
    /// Trials run over all variants, and of which failed.
    pub(crate) trials: usize,
    /// See `trials`.
    pub(crate) failed: usize,
    /// The variants, in file order.
    pub(crate) variants: Vec<Variant>,
    /// The table.
    pub(crate) rows: Vec<SensitivityRow>,
}

/// The file each variant's folder records its response in.
pub(crate) const RESPONSE_FILE: &str = "operator_response.toml";

/// Runs the experiment `config_path` once per variant of `sensitivity_path` into a new folder
/// (`wanted`, or `wanted-2`, …), then writes the table. Progress: each experiment's progress
/// bar (with `show_progress`) and a line per variant on stderr.
pub(crate) fn run_sensitivity(
    config_path: &Path,
    sensitivity_path: &Path,
    wanted: &Path,
    jobs: usize,
    show_progress: bool,
) -> crate::Result<SensitivityOutcome> {
    let cfg = super::ExperimentConfig::from_file(config_path)?;
    let trial = TrialConfig::from_file(&cfg.trial_config)?;
    let variants = read_variants(sensitivity_path, trial.operator.response)?;
    let text =
        std::fs::read_to_string(sensitivity_path).map_err(Error::io("read", sensitivity_path))?;
    let dir = crate::trial::create_run_dir(wanted)?;
    let copy = dir.join("sensitivity.toml");
    std::fs::write(&copy, text).map_err(Error::io("write", &copy))?;
    let started = std::time::Instant::now();
    let (mut trials, mut failed) = (0, 0);
    let mut outcomes = Vec::with_capacity(variants.len());
    for (i, v) in variants.iter().enumerate() {
        let out = super::run_experiment_with(
            config_path,
            &dir.join(&v.name),
            jobs,
            show_progress,
            &super::Overrides {
                seed: None,
                response: Some(v.response),
            },
        )?;
        let record = out.dir.join(RESPONSE_FILE);
        let body = toml::to_string(&v.response).map_err(|e| Error::Internal {
            reason: format!("the operator response serialises to TOML: {e}"),
        })?;
        std::fs::write(
            &record,
            format!(
                "# The simulated operator's [operator.response] of variant {:?} (SIMULATED; \
                 src/trial/config.rs, OperatorResponse).\n{body}",
                v.name
            ),
        )
        .map_err(Error::io("write", &record))?;
        trials += out.trials;
        failed += out.failed;
        outcomes.push((v.name.clone(), aggregate::read_outcomes(&out.dir)?));
        eprintln!(
            "[simulation] variant {}/{} {:?}: {} trials ({} failed), {:.0} s elapsed",
            i + 1,
            variants.len(),
            v.name,
            out.trials,
            out.failed,
            started.elapsed().as_secs_f64()
        );
    }
    let rows = sensitivity_table(&outcomes, &cfg.policies[0], &cfg.policies[1])?;
    write(&dir, [&cfg.policies[0], &cfg.policies[1]], &variants, &rows)?;
    Ok(SensitivityOutcome {
        dir,
        trials,
        failed,
        variants,
        rows,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;

    /// A hand-made trial outcome: `metrics[0]` (completion time) and `metrics[1]` (hesitation
    /// share) as given, every other metric 1.0 (equal under both policies: not testable).
    fn outcome(participant: &str, policy: &str, completion: f64, share: f64) -> TrialOutcome {
        let mut metrics = [1.0; METRICS.len()];
        metrics[0] = completion;
        metrics[1] = share;
        TrialOutcome {
            participant: participant.into(),
            condition: "L1".into(),
            policy: policy.into(),
            simulated: true,
            metrics,
            rules_adopted: BTreeMap::new(),
        }
    }

    /// Computed by hand. Four participants, one condition, adaptive − fixed:
    /// - variant `calm`: completion differences −1, −2, −3, −4 (all negative, no ties or
    ///   zeros: exact test): R+ = 0, R− = 10, r = (0 − 10)/10 = −1, p = 2·P(T+ ≤ 0) = 2/16 =
    ///   0.125, median −2.5; hesitation-share differences +0.1, −0.2, +0.3, +0.4 (ranks 1, 2,
    ///   3, 4): R+ = 8, R− = 2, r = 0.6, p = 2·P(T− ≤ 2) = 2·3/16 = 0.375 (subsets of
    ///   {1, 2, 3, 4} summing to ≤ 2: {}, {1}, {2}), median 0.2. Holm over the two: 2·0.125 =
    ///   0.25, then max(0.25, 0.375) = 0.375.
    /// - variant `tense`: completion differences −4 in every pair (four ties at rank 2.5, no
    ///   zeros: the sign-flip permutation distribution): R− = 10, r = −1, p = 2·P(T+ ≤ 0) =
    ///   2/16 = 0.125, median −4; the share is equal (every difference zero: not testable), so
    ///   Holm over the one test is its p.
    #[test]
    fn the_sensitivity_table_matches_a_hand_computed_example() {
        let mut calm = Vec::new();
        let mut tense = Vec::new();
        for (i, (dc, ds)) in [(-1.0, 0.1), (-2.0, -0.2), (-3.0, 0.3), (-4.0, 0.4)]
            .into_iter()
            .enumerate()
        {
            let p = format!("P{i}");
            calm.push(outcome(&p, "fixed", 100.0, 0.5));
            calm.push(outcome(&p, "adaptive", 100.0 + dc, 0.5 + ds));
            tense.push(outcome(&p, "fixed", 100.0, 0.5));
            tense.push(outcome(&p, "adaptive", 96.0, 0.5));
        }
        let rows = sensitivity_table(
            &[("calm".into(), calm), ("tense".into(), tense)],
            "adaptive",
            "fixed",
        )
        .unwrap();
        assert_eq!(rows.len(), 2 * METRICS.len());
        let close = |a: f64, b: f64| (a - b).abs() < 1e-12;
        let get = |v: &str, m: &str| {
            rows.iter()
                .find(|r| r.variant == v && r.metric == m)
                .unwrap()
                .effect
        };
        let c = get("calm", "completion_time_s");
        assert_eq!(c.n_pairs, 4);
        assert!(close(c.median_difference, -2.5), "{c:?}");
        assert!(close(c.rank_biserial, -1.0), "{c:?}");
        assert!(close(c.p_value, 0.125), "{c:?}");
        assert!(close(c.p_holm, 0.25), "{c:?}");
        let h = get("calm", "hesitation_share");
        assert!(close(h.median_difference, 0.2), "{h:?}");
        assert!(close(h.rank_biserial, 0.6), "{h:?}");
        assert!(close(h.p_value, 0.375), "{h:?}");
        assert!(close(h.p_holm, 0.375), "{h:?}");
        // The other metrics are equal under both policies: pairs, no test.
        let o = get("calm", "operator_idle_s");
        assert_eq!(o.n_pairs, 4);
        assert_eq!(o.median_difference, 0.0);
        assert!(o.p_value.is_nan() && o.p_holm.is_nan() && o.rank_biserial.is_nan());
        let t = get("tense", "completion_time_s");
        assert!(close(t.median_difference, -4.0), "{t:?}");
        assert!(close(t.rank_biserial, -1.0), "{t:?}");
        assert!(close(t.p_value, 0.125), "{t:?}");
        assert!(close(t.p_holm, 0.125), "one test: Holm is p, {t:?}");
        assert!(get("tense", "hesitation_share").p_value.is_nan());
        // Rows come variant by variant, metrics in METRICS order.
        assert_eq!(rows[0].variant, "calm");
        assert_eq!(rows[METRICS.len()].variant, "tense");
        assert_eq!(rows[1].metric, METRICS[1]);

        // The CSV holds the same numbers; the report says SIMULATED.
        let tmp = tempfile::tempdir().unwrap();
        let variants = ["calm", "tense"].map(|n| Variant {
            name: n.into(),
            response: OperatorResponse::default(),
        });
        write(tmp.path(), ["adaptive", "fixed"], &variants, &rows).unwrap();
        let csv = std::fs::read_to_string(tmp.path().join("sensitivity.csv")).unwrap();
        assert_eq!(csv.lines().count(), 1 + 2 * METRICS.len());
        assert!(
            csv.contains("calm,completion_time_s,4,-2.5,-1,0.125,0.25\n"),
            "{csv}"
        );
        assert!(csv.contains("calm,operator_idle_s,4,0,,,\n"), "{csv}");
        let md = std::fs::read_to_string(tmp.path().join("sensitivity.md")).unwrap();
        assert!(md.contains("SIMULATED"), "{md}");
        assert!(
            md.contains("| completion_time_s | calm | 4 | -2.500 | -1.000 | 0.125 | 0.250 |"),
            "{md}"
        );
    }

    #[test]
    fn variants_start_from_the_base_and_bad_files_are_refused_by_name() {
        let base = OperatorResponse::default();
        let v = parse_variants(
            "[[variant]]\nname = \"none\"\nk_speed = 0.0\nk_acc = 0.0\nsurprise_p = 0.0\n\
             [[variant]]\nname = \"shipped\"\n",
            base,
        )
        .unwrap();
        assert_eq!(v.len(), 2);
        assert_eq!(v[0].name, "none");
        assert_eq!(
            v[0].response,
            OperatorResponse {
                k_speed: 0.0,
                k_acc: 0.0,
                surprise_p: 0.0,
                ..base
            }
        );
        assert_eq!(v[1].response, base);
        for (text, needle) in [
            ("", "lists no variant"),
            ("variant = []", "lists no variant"),
            ("[[variant]]\nname = \"a\"\nk_sped = 1.0\n", "k_sped"),
            ("[[variants]]\nname = \"a\"\n", "variants"),
            ("[[variant]]\nk_speed = 1.0\n", "name"),
            (
                "[[variant]]\nname = \"a\"\n[[variant]]\nname = \"a\"\n",
                "\"a\" names two variants",
            ),
            ("[[variant]]\nname = \"a b\"\n", "variant[0].name"),
            ("[[variant]]\nname = \"\"\n", "variant[0].name"),
            (
                "[[variant]]\nname = \"x\"\nk_speed = -1.0\n",
                "variant \"x\": k_speed` must be finite and >= 0, got -1",
            ),
            (
                "[[variant]]\nname = \"x\"\nsurprise_p = 1.5\n",
                "surprise_p` must be a probability in [0, 1], got 1.5",
            ),
            (
                "[[variant]]\nname = \"x\"\nref_speed_m_s = 0.0\n",
                "ref_speed_m_s` must be finite and > 0, got 0",
            ),
        ] {
            let e = parse_variants(text, base)
                .unwrap_err()
                .with_causes()
                .to_string();
            assert!(e.contains(needle), "{text:?}: {e}");
        }
        // From a file: the error names it.
        let tmp = tempfile::tempdir().unwrap();
        let path = tmp.path().join("s.toml");
        std::fs::write(&path, "variant = []").unwrap();
        let e = read_variants(&path, base)
            .unwrap_err()
            .with_causes()
            .to_string();
        assert!(
            e.contains("s.toml") && e.contains("lists no variant"),
            "{e}"
        );
    }

    /// The shipped example parses: `none` turns every response off, `shipped` is the shipped
    /// trial config's, `double` doubles every gain.
    #[test]
    fn the_shipped_sensitivity_file_parses() {
        let base = TrialConfig::shipped().unwrap().operator.response;
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/sensitivity.toml");
        let v = read_variants(&path, base).unwrap();
        let names: Vec<&str> = v.iter().map(|v| v.name.as_str()).collect();
        assert_eq!(names, ["none", "shipped", "double"]);
        let none = v[0].response;
        assert_eq!(
            (
                none.k_speed,
                none.k_acc,
                none.surprise_p,
                none.surprise_stress
            ),
            (0.0, 0.0, 0.0, 0.0)
        );
        assert_eq!(v[1].response, base);
        let d = v[2].response;
        assert_eq!(
            (
                d.k_speed,
                d.k_acc,
                d.k_duration,
                d.surprise_p,
                d.surprise_stress
            ),
            (
                2.0 * base.k_speed,
                2.0 * base.k_acc,
                2.0 * base.k_duration,
                2.0 * base.surprise_p,
                2.0 * base.surprise_stress
            )
        );
        assert_eq!(
            (d.ref_speed_m_s, d.ref_acc_m_s2),
            (base.ref_speed_m_s, base.ref_acc_m_s2)
        );
    }
}
