//! `experiment_summary.json` and the self-contained `experiment_report.html` (box plots per
//! policy × condition for every metric, embedded as base64 PNGs, each labelled SIMULATED).
//!
//! # Statistics
//! - **Table**: per policy × condition and metric, n (present values), mean, median.
//! - **Policy comparison**: `policies[0]` − `policies[1]`, Wilcoxon signed-rank, one pair per
//!   participant (their mean over the conditions run under both policies). Zero differences are
//!   dropped before ranking (Wilcox's method, scipy's default); the p-value is exact when there
//!   are neither ties nor zeros, otherwise the exact sign-flip permutation distribution
//!   (n ≤ 13) or the tie-corrected normal approximation (scipy's `auto`). Holm's step-down
//!   adjustment across the metrics that could be tested. Effect sizes: the matched-pairs
//!   rank-biserial correlation (Kerby 2014) and the median paired difference.
//! - **Conditions**: per policy and metric, Friedman's test across the conditions with the tie
//!   correction, blocks = participants who ran every condition; effect size Kendall's W.

use std::path::{Path, PathBuf};

use crate::Error;
use plotters::prelude::*;
use policies::Schedule;
use serde_json::{Value, json};

use super::aggregate::{self, METRICS, TrialOutcome};
use super::{ExperimentConfig, TrialRun};
use crate::report::plot::{FAMILY, register_font};

/// `experiment_summary.json`.
pub(crate) const SUMMARY_FILE: &str = "experiment_summary.json";
/// `experiment_report.html`.
pub(crate) const REPORT_FILE: &str = "experiment_report.html";

/// Everything the report shows.
#[derive(Debug)]
pub(crate) struct Inputs<'a> {
    /// The experiment file.
    pub(crate) config: &'a ExperimentConfig,
    /// The schedule drawn from it.
    pub(crate) schedule: &'a Schedule,
    /// Every trial run, in schedule order.
    pub(crate) runs: &'a [TrialRun],
    /// The summaries read back from the trial folders.
    pub(crate) outcomes: &'a [TrialOutcome],
    /// Worker threads.
    pub(crate) jobs: usize,
    /// Wall time up to the report [s].
    pub(crate) wall_s: f64,
}

/// Metric labels with units, in [`METRICS`] order.
pub(crate) const LABELS: [&str; METRICS.len()] = [
    "completion time [s]",
    "hesitation share (assessed) [-]",
    "mean HRC-CWL (cumulative) [-]",
    "operator idle time [s]",
    "robot idle time [s]",
    "robot wait, sum over handovers [s]",
    "operator wait, sum over handovers [s]",
    "handovers with a returned part [-]",
    "share of the trial a part waited at the handover point [-]",
];

/// A number for JSON: non-finite values become `null`.
fn num(x: f64) -> Value {
    if x.is_finite() { json!(x) } else { Value::Null }
}

/// Writes `experiment_summary.json`, the box-plot PNGs and `experiment_report.html` into `dir`;
/// returns the report's path.
pub(crate) fn write(dir: &Path, inp: &Inputs<'_>) -> crate::Result<PathBuf> {
    let [a, b] = [&inp.config.policies[0], &inp.config.policies[1]];
    let conditions: Vec<String> = inp
        .config
        .conditions
        .iter()
        .map(|c| c.to_string())
        .collect();
    let table = aggregate::table(inp.outcomes);
    let tests = if inp.outcomes.is_empty() {
        Vec::new()
    } else {
        aggregate::compare_policies(inp.outcomes, a, b).unwrap_or_default()
    };
    let friedman: Vec<(String, Vec<_>)> = inp
        .config
        .policies
        .iter()
        .map(|p| {
            (
                p.clone(),
                aggregate::friedman_across_conditions(inp.outcomes, p),
            )
        })
        .collect();
    let failures: Vec<&TrialRun> = inp.runs.iter().filter(|r| r.error.is_some()).collect();
    let simulated = inp.outcomes.iter().all(|o| o.simulated);
    let fired = aggregate::rules_fired(inp.outcomes);

    // ---- JSON
    let summary = json!({
        "simulated": simulated,
        "design": {
            "participants": inp.config.participants,
            "conditions": conditions,
            "policies": inp.config.policies,
            "seed": inp.config.seed,
            "trial_config": inp.config.trial_config,
            "square_rows": inp.schedule.square_rows,
            "complete": inp.schedule.complete,
        },
        "rules_fired": fired.iter().map(|((p, k), (n, trials))| json!({
            "policy": p, "rule": k, "adoptions": n, "trials": trials,
        })).collect::<Vec<_>>(),
        "jobs": inp.jobs,
        "wall_time_s": inp.wall_s,
        "metric_sources": {
            "hesitation_share": "hesitation_share.assessed",
            "hrc_cwl_mean": "hrc_cwl_mean.cumulative",
            "robot_wait_s": "sum of non-null handovers[].robot_wait_s",
            "operator_wait_s": "sum of non-null handovers[].operator_wait_s",
            "return_rate": "share of handovers[] with returned = true",
            "part_wait_share": "sum of non-null handovers[].robot_wait_s / completion_time_s",
        },
        "trials": inp.runs.iter().map(|r| json!({
            "participant": r.trial.participant,
            "position": r.trial.position,
            "condition": r.trial.condition.as_str(),
            "policy": r.trial.policy.as_str(),
            "seed": r.trial.seed,
            "folder": r.trial.folder,
            "wall_s": r.wall_s,
            "ok": r.error.is_none(),
            "error": r.error,
        })).collect::<Vec<_>>(),
        "failures": failures.len(),
        "table": table.iter().map(|((p, c), cells)| json!({
            "policy": p,
            "condition": c,
            "metrics": METRICS.iter().zip(cells).map(|(m, cell)| (m.to_string(), json!({
                "n": cell.n, "mean": num(cell.mean), "median": num(cell.median),
            }))).collect::<serde_json::Map<_, _>>(),
        })).collect::<Vec<_>>(),
        "policy_comparison": {
            "a": a,
            "b": b,
            "difference": "a - b, one pair per participant (mean over conditions)",
            "test": "Wilcoxon signed-rank, two-sided; zeros dropped (Wilcox); scipy 'auto' method; Holm across testable metrics",
            "metrics": tests.iter().map(|t| {
                let mut o = json!({
                    "metric": METRICS[t.metric],
                    "n_pairs": t.n_pairs,
                    "median_difference": num(t.median_difference),
                    "p_holm": t.p_holm,
                });
                match &t.wilcoxon {
                    Ok(w) => {
                        o["statistic"] = num(w.statistic);
                        o["r_plus"] = num(w.r_plus);
                        o["r_minus"] = num(w.r_minus);
                        o["n_zero"] = json!(w.n_zero);
                        o["z"] = w.z.map_or(Value::Null, num);
                        o["p_value"] = num(w.p_value);
                        o["method"] = json!(format!("{:?}", w.method));
                        o["rank_biserial"] = num(w.rank_biserial);
                    }
                    Err(e) => o["not_tested"] = json!(e.to_string()),
                }
                o
            }).collect::<Vec<_>>(),
        },
        "friedman_across_conditions": friedman.iter().map(|(p, rs)| (p.clone(), Value::Array(
            rs.iter().zip(METRICS).map(|(r, m)| match r {
                Ok(f) => json!({
                    "metric": m, "n": f.n, "k": f.k, "chi2": num(f.statistic), "df": f.df,
                    "p_value": num(f.p_value), "tie_correction": num(f.tie_correction),
                    "kendall_w": num(f.kendall_w),
                }),
                Err(e) => json!({"metric": m, "not_tested": e.to_string()}),
            }).collect()))).collect::<serde_json::Map<_, _>>(),
    });
    let summary_path = dir.join(SUMMARY_FILE);
    let mut text = serde_json::to_string_pretty(&summary)
        .map_err(Error::json("write", summary_path.display()))?;
    text.push('\n');
    std::fs::write(&summary_path, text).map_err(Error::io("write", &summary_path))?;

    // ---- Plots
    let mut pngs = Vec::new();
    for (m, name) in METRICS.iter().enumerate() {
        let path = dir.join(format!("box_{name}.png"));
        box_plot(&path, inp.outcomes, &inp.config.policies, &conditions, m)?;
        pngs.push(path);
    }

    // ---- HTML
    let mut h = String::new();
    let w = &mut h;
    w.push_str(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\
         <title>SIMULATED policy A/B experiment</title><style>\
         body{font-family:sans-serif;max-width:1100px;margin:2em auto;padding:0 1em}\
         table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #bbb;padding:3px 7px;\
         text-align:right}th{background:#eee}td:first-child,th:first-child{text-align:left}\
         .sim{background:#fff3cd;border:2px solid #e0a800;padding:.6em 1em;font-weight:bold}\
         img{max-width:100%}</style></head><body>\n",
    );
    w.push_str("<h1>SIMULATED policy A/B experiment</h1>\n");
    w.push_str(&format!(
        "<p class=\"sim\">SIMULATION: every trial ran with the simulated operator (a seeded \
         stochastic model of the gearbox task) and the in-process simulated robot. These are not \
         human data.{}</p>\n",
        if simulated {
            ""
        } else {
            " (Some summaries do not say meta.simulated = true.)"
        }
    ));
    w.push_str(&format!(
        "<p>{} participants × conditions {} × policies {} / {}; seed {}; Williams design with {} \
         rows ({}). {} trials, {} failed; {} worker(s), {:.1} s wall time.</p>\n",
        inp.config.participants,
        conditions.join(", "),
        esc(a),
        esc(b),
        inp.config.seed,
        inp.schedule.square_rows,
        if inp.schedule.complete {
            "complete: exact balance"
        } else {
            "incomplete: the last block is a partial square"
        },
        inp.runs.len(),
        failures.len(),
        inp.jobs,
        inp.wall_s
    ));
    if !failures.is_empty() {
        w.push_str("<h2>Failed trials</h2>\n<table><tr><th>trial</th><th>error</th></tr>\n");
        for r in &failures {
            w.push_str(&format!(
                "<tr><td>{}</td><td style=\"text-align:left\">{}</td></tr>\n",
                esc(&r.trial.folder),
                esc(r.error.as_deref().unwrap_or(""))
            ));
        }
        w.push_str("</table>\n");
    }
    w.push_str(
        "<p>Metrics from each trial's <code>summary.json</code>: hesitation share = \
         <code>hesitation_share.assessed</code>; mean HRC-CWL = \
         <code>hrc_cwl_mean.cumulative</code>; waits = sums of the non-null per-handover waits; \
         null values are missing and left out.</p>\n",
    );

    w.push_str("<h2>Policy × condition (SIMULATED)</h2>\n<table><tr><th>metric</th>");
    for (p, c) in table.keys() {
        w.push_str(&format!("<th>{} {}</th>", esc(p), esc(c)));
    }
    w.push_str("</tr>\n");
    for (m, label) in LABELS.iter().enumerate() {
        w.push_str(&format!("<tr><td>{label}</td>"));
        for cells in table.values() {
            let c = cells[m];
            w.push_str(&format!(
                "<td>{} / {} (n={})</td>",
                fmt(c.mean),
                fmt(c.median),
                c.n
            ));
        }
        w.push_str("</tr>\n");
    }
    w.push_str("</table><p>Cells: mean / median (n).</p>\n");

    w.push_str(
        "<h2>Rules fired (SIMULATED)</h2>\n<p>How often each policy adopted each rule of its \
         table, summed over the trials (<code>adaptation_changes.by_indicator</code>), and in \
         how many trials at least once. The first adoption of <code>none</code> at the start \
         is not a change and is not counted.</p>\n<table><tr><th>policy</th><th>rule</th>\
         <th>adoptions</th><th>trials</th></tr>\n",
    );
    for ((p, k), (n, trials)) in &fired {
        w.push_str(&format!(
            "<tr><td>{}</td><td>{}</td><td>{n}</td><td>{trials}</td></tr>\n",
            esc(p),
            esc(k)
        ));
    }
    w.push_str("</table>\n");

    w.push_str(&format!(
        "<h2>{} vs {} (SIMULATED)</h2>\n<p>Wilcoxon signed-rank on {} − {}, one pair per \
         participant (mean over conditions); zero differences dropped (Wilcox), p exact or \
         permutation for small n, else normal with tie correction; Holm across the testable \
         metrics. Effect sizes: rank-biserial r (positive: {} higher) and the median \
         difference.</p>\n<table><tr><th>metric</th><th>pairs</th><th>zeros</th><th>R+</th>\
         <th>R−</th><th>method</th><th>p</th><th>p (Holm)</th><th>r</th><th>median diff</th></tr>\n",
        esc(a),
        esc(b),
        esc(a),
        esc(b),
        esc(a)
    ));
    for t in &tests {
        w.push_str(&format!(
            "<tr><td>{}</td><td>{}</td>",
            LABELS[t.metric], t.n_pairs
        ));
        match &t.wilcoxon {
            Ok(r) => w.push_str(&format!(
                "<td>{}</td><td>{}</td><td>{}</td><td>{:?}</td><td>{}</td><td>{}</td><td>{}</td>",
                r.n_zero,
                fmt(r.r_plus),
                fmt(r.r_minus),
                r.method,
                fmt(r.p_value),
                t.p_holm.map_or("–".into(), fmt),
                fmt(r.rank_biserial)
            )),
            Err(e) => w.push_str(&format!(
                "<td colspan=\"7\" style=\"text-align:left\">not tested: {}</td>",
                esc(&e.to_string())
            )),
        }
        w.push_str(&format!("<td>{}</td></tr>\n", fmt(t.median_difference)));
    }
    w.push_str("</table>\n");

    w.push_str(
        "<h2>Across conditions, per policy (SIMULATED)</h2>\n<p>Friedman test with the tie \
         correction; blocks are the participants who ran every condition under the policy. \
         Effect size: Kendall's W.</p>\n<table><tr><th>metric</th>",
    );
    for (p, _) in &friedman {
        w.push_str(&format!("<th>{} χ² (df)</th><th>p</th><th>W</th>", esc(p)));
    }
    w.push_str("</tr>\n");
    for (m, label) in LABELS.iter().enumerate() {
        w.push_str(&format!("<tr><td>{label}</td>"));
        for (_, rs) in &friedman {
            match &rs[m] {
                Ok(f) => w.push_str(&format!(
                    "<td>{} ({}), n={}</td><td>{}</td><td>{}</td>",
                    fmt(f.statistic),
                    f.df,
                    f.n,
                    fmt(f.p_value),
                    fmt(f.kendall_w)
                )),
                Err(e) => w.push_str(&format!("<td colspan=\"3\">{}</td>", esc(&e.to_string()))),
            }
        }
        w.push_str("</tr>\n");
    }
    w.push_str("</table>\n<h2>Box plots (SIMULATED)</h2>\n");
    for (path, label) in pngs.iter().zip(LABELS) {
        let bytes = std::fs::read(path).map_err(Error::io("read", path))?;
        w.push_str(&format!(
            "<h3>{label}</h3>\n<img alt=\"SIMULATED: {label} per policy and condition\" \
             src=\"data:image/png;base64,{}\">\n",
            base64(&bytes)
        ));
    }
    w.push_str("<h2>Trials</h2>\n<table><tr><th>folder</th><th>seed</th><th>wall [s]</th><th>status</th></tr>\n");
    for r in inp.runs {
        w.push_str(&format!(
            "<tr><td>{}</td><td>{}</td><td>{:.2}</td><td>{}</td></tr>\n",
            esc(&r.trial.folder),
            r.trial.seed,
            r.wall_s,
            if r.error.is_some() { "FAILED" } else { "ok" }
        ));
    }
    w.push_str("</table>\n</body></html>\n");
    let path = dir.join(REPORT_FILE);
    std::fs::write(&path, h).map_err(Error::io("write", &path))?;
    Ok(path)
}

/// A number for the HTML tables: 4 significant-ish decimals, `–` for NaN.
fn fmt(x: f64) -> String {
    if !x.is_finite() {
        "–".into()
    } else if x != 0.0 && x.abs() < 1e-3 {
        format!("{x:.2e}")
    } else {
        format!("{x:.4}")
    }
}

/// HTML-escapes text.
fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// Standard base64 (RFC 4648, with padding).
pub(crate) fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            *chunk.get(1).unwrap_or(&0),
            *chunk.get(2).unwrap_or(&0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for i in 0..4 {
            if i <= chunk.len() {
                out.push(A[(n >> (18 - 6 * i) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

// Okabe–Ito, as in the other plots.
const POLICY_COLOURS: [RGBColor; 2] = [RGBColor(0, 114, 178), RGBColor(230, 159, 0)];

/// One metric's box plot: a box per policy within each condition (median, quartiles by linear
/// interpolation, whiskers to the most extreme values within 1.5 IQR), every trial as a dot.
fn box_plot(
    path: &Path,
    outcomes: &[TrialOutcome],
    policies: &[String],
    conditions: &[String],
    m: usize,
) -> crate::Result<()> {
    register_font()?;
    let plot = |e: &dyn std::fmt::Display| Error::Plot {
        path: path.to_path_buf(),
        reason: e.to_string(),
    };
    let values: Vec<Vec<Vec<f64>>> = conditions
        .iter()
        .map(|c| {
            policies
                .iter()
                .map(|p| aggregate::cell_values(outcomes, p, c, m))
                .collect()
        })
        .collect();
    let all = values.iter().flatten().flatten().copied();
    let (lo, hi) = all.fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), x| {
        (l.min(x), h.max(x))
    });
    let (lo, hi) = if lo.is_finite() { (lo, hi) } else { (0.0, 1.0) };
    let pad = if hi > lo {
        0.08 * (hi - lo)
    } else {
        0.5_f64.max(0.05 * hi.abs())
    };
    let (y0, y1) = (lo - pad, hi + pad);

    let root = BitMapBackend::new(path, (900, 480)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| plot(&e))?;
    let nc = conditions.len();
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!("SIMULATED: {}", LABELS[m]),
            (FAMILY, 22).into_font().color(&BLACK),
        )
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(-0.5..(nc as f64 - 0.5), y0..y1)
        .map_err(|e| plot(&e))?;
    let names = conditions.to_vec();
    let x_fmt = move |x: &f64| {
        let i = x.round();
        if (x - i).abs() < 1e-9 && i >= 0.0 && (i as usize) < names.len() {
            names[i as usize].clone()
        } else {
            String::new()
        }
    };
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(4 * nc + 1)
        .x_label_formatter(&x_fmt)
        .x_desc("condition")
        .y_desc(LABELS[m])
        .axis_desc_style((FAMILY, 17).into_font().color(&BLACK))
        .label_style((FAMILY, 15).into_font().color(&BLACK))
        .draw()
        .map_err(|e| plot(&e))?;

    let width = 0.32;
    for (ci, per_policy) in values.iter().enumerate() {
        for (pi, xs) in per_policy.iter().enumerate() {
            let colour = POLICY_COLOURS[pi % POLICY_COLOURS.len()];
            let x = ci as f64 + (pi as f64 - (policies.len() as f64 - 1.0) / 2.0) * 0.4;
            if xs.is_empty() {
                continue;
            }
            let q1 = aggregate::quantile(xs, 0.25);
            let q2 = aggregate::quantile(xs, 0.5);
            let q3 = aggregate::quantile(xs, 0.75);
            let iqr = q3 - q1;
            let w_lo = xs
                .iter()
                .copied()
                .find(|&v| v >= q1 - 1.5 * iqr)
                .unwrap_or(q1);
            let w_hi = xs
                .iter()
                .rev()
                .copied()
                .find(|&v| v <= q3 + 1.5 * iqr)
                .unwrap_or(q3);
            let (l, r) = (x - width / 2.0, x + width / 2.0);
            chart
                .draw_series([
                    Rectangle::new([(l, q1), (r, q3)], colour.mix(0.25).filled()),
                    Rectangle::new([(l, q1), (r, q3)], colour.stroke_width(2)),
                ])
                .map_err(|e| plot(&e))?;
            let line = |a: (f64, f64), b: (f64, f64), sw: u32| {
                PathElement::new(vec![a, b], colour.stroke_width(sw))
            };
            chart
                .draw_series([
                    line((l, q2), (r, q2), 3),
                    line((x, q3), (x, w_hi), 2),
                    line((x, q1), (x, w_lo), 2),
                    line((x - width / 4.0, w_hi), (x + width / 4.0, w_hi), 2),
                    line((x - width / 4.0, w_lo), (x + width / 4.0, w_lo), 2),
                ])
                .map_err(|e| plot(&e))?;
            // Every trial as a dot, spread across the box so ties stay visible.
            let n = xs.len();
            chart
                .draw_series(xs.iter().enumerate().map(|(k, &v)| {
                    let dx = if n > 1 {
                        (k as f64 / (n - 1) as f64 - 0.5) * width * 0.7
                    } else {
                        0.0
                    };
                    Circle::new((x + dx, v), 3, BLACK.mix(0.7).filled())
                }))
                .map_err(|e| plot(&e))?;
        }
    }
    for (pi, p) in policies.iter().enumerate() {
        let colour = POLICY_COLOURS[pi % POLICY_COLOURS.len()];
        chart
            .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())
            .map_err(|e| plot(&e))?
            .label(p.as_str())
            .legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 16, y + 6)], colour.filled()));
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font((FAMILY, 15).into_font().color(&BLACK))
        .draw()
        .map_err(|e| plot(&e))?;
    root.present().map_err(|e| plot(&e))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc4648_vectors() {
        for (input, want) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(base64(input.as_bytes()), want);
        }
    }
}
