//! Issue 14, point 1 (hand kinematics): reach, hold and transport speed profiles of the taker's
//! and the giver's right hands in the bundled KTH human–human handover
//! (`data/human-motion/kth-handover/`, OptiTrack at 120 Hz, 801 rows; MIT licence, provenance in
//! its README), to fit the simulated operator's reach and hesitation motion
//! (`src/trial/operator.rs`, `COMMON`) to them.
//!
//! What is real and what is derived:
//! - **real**: the rigid-body positions (`*_pose_saved.csv`) and the force magnitudes
//!   (`Wrench_*_saved.csv`) of the recording;
//! - **derived** (this program): speeds, the handover events (by [`read_recording`], the
//!   repository's reader, with its default thresholds: reach onset, grasp = taker |F| > 5 N,
//!   release = giver |F| < 1 N), the phases and their statistics;
//! - **SIMULATED** (rows with hand `model`): Gaussian noise pushed through the assessment's
//!   One-Euro hand filter, and the operator model's own working motion, as checks of the
//!   proposed operator constants. They are labelled as such in the CSV (`source` column).
//!
//! # Speed
//! Velocity is the centred difference over ±[`HALF_WINDOW`] rows, (x[k+h] − x[k−h]) / (2h / 120 Hz)
//! (h = 6: 100 ms, the same as a centred 12-sample moving average of the one-step finite-difference
//! velocity; first zero of its response at 10 Hz), truncated at the ends of the recording. Speed
//! is its norm. Peaks are also given with h = 3 (50 ms) as a sensitivity check.
//!
//! # Segmentation (per hand; events from the force sensors)
//! With v_move = [`V_MOVE`] = 0.10 m/s (the assessment's v_max: above it a hand can never count as
//! low motion):
//! - **approach** (taker: *reach*; giver: *transport to the handover point*): the maximal run of
//!   rows with v ≥ v_move that contains the hand's peak speed before the grasp (for the giver the
//!   search starts at its own regrasp, the first row after its |F| fell below 1 N where it
//!   exceeds 5 N again);
//! - before it: *rest* (taker) / *preparation* (giver: sets the baton down and grasps it again);
//! - **hold**: from the end of the approach to the release (includes the grasp);
//! - **depart** (taker: *transport*, carrying the baton away; giver: *withdraw*): from the release
//!   to the first row after the hand's peak speed (after the release) where v < v_move;
//! - after it: *rest_after*.
//!
//! The handover point of a hand is its own position at the grasp row (the hand rigid body's
//! origin is at the wrist, ≈ 0.21 m from the baton's origin while holding it, so the baton's
//! position is not the point the wrist goes to). "Near" is the contiguous run of rows around the
//! grasp where the hand is within 5 / 10 cm of that point.
//!
//! # Stillness
//! For every phase, also at the cue rate of the assessment: the rows decimated to 30 Hz (every
//! 4th), detrended position σ per axis (linear least squares; axis-RMS reported), σ from first
//! differences (std(Δx)/√2), lag-1 autocorrelation, and v_h, the §7 filtered speed (One-Euro with
//! the `[hesitation.one_euro]` defaults: 1 Hz, β 0.05, derivative cutoff 1 Hz, the same
//! arithmetic as the assessor: |x̂_k − x̂_{k−1}| / Δt) run over the whole recording from row 0;
//! frames before 0.5 s are not used.
//!
//! Run with
//! `cargo run --release -p assess --example kth_kinematics -- [out_dir] [kth_dir]`
//! (defaults `docs/calibration` and `data/human-motion/kth-handover`, relative to the repository
//! root). Writes `kth_kinematics.csv` and `kth_kinematics.png` (drawn with `plotters`, a
//! dev-dependency of `assess`, in the DejaVu Sans font the root crate embeds). Deterministic:
//! fixed-seed SplitMix64 for the simulated rows.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use assess::filter::OneEuro3;
use assess::io::kth::{KTH_RATE_HZ, KthOptions, read_recording, rotate_xyzw};
use assess::{OneEuroConfig, Vec3};
use plotters::prelude::*;
use plotters::style::FontStyle;
use plotters::style::text_anchor::{HPos, Pos, VPos};

#[path = "support/stats.rs"]
mod stats;

use stats::mean;

type Res<T> = Result<T, Box<dyn std::error::Error>>;

/// Half-window of the centred difference [rows] (6 rows = 50 ms each side at 120 Hz).
const HALF_WINDOW: usize = 6;
/// Half-window of the sensitivity check [rows].
const HALF_WINDOW_SHORT: usize = 3;
/// Moving / still threshold of the segmentation [m/s] (the assessment's v_max).
const V_MOVE: f64 = 0.10;
/// The assessment's v_min [m/s].
const V_MIN: f64 = 0.03;
/// Decimation to the assessment's 30 Hz cue rate [rows].
const DECIMATE: usize = 4;
/// Frames of the filtered speed before this time are not used (filter warm-up) [s].
const WARMUP_S: f64 = 0.5;
/// Perception noise of a still hand seen by the hand model with depth, per axis [m]
/// (`cue_noise.csv`, pose_sitting.jpg 0.75, still, depth, hand_right: σ axis-RMS 0.84 mm; the
/// largest with-depth value of the hand model).
const PERCEPTION_HAND_SIGMA_M: f64 = 0.00084;
/// Frames of the simulated noise checks.
const SIM_FRAMES: usize = 30_000;

/// One CSV row.
struct Row {
    subject: String,
    phase: String,
    measure: String,
    value: f64,
    unit: &'static str,
    first_row: Option<usize>,
    last_row: Option<usize>,
    source: &'static str,
}

#[derive(Default)]
struct Out {
    rows: Vec<Row>,
}

impl Out {
    #[allow(clippy::too_many_arguments)]
    fn push(
        &mut self,
        subject: &str,
        phase: &str,
        measure: &str,
        value: f64,
        unit: &'static str,
        span: Option<(usize, usize)>,
        source: &'static str,
    ) {
        self.rows.push(Row {
            subject: subject.to_string(),
            phase: phase.to_string(),
            measure: measure.to_string(),
            value,
            unit,
            first_row: span.map(|s| s.0),
            last_row: span.map(|s| s.1.saturating_sub(1)),
            source,
        });
    }

    fn csv(&self) -> String {
        let mut s = String::from("subject,phase,measure,value,unit,first_row,last_row,source\n");
        for r in &self.rows {
            let v = if r.value.is_finite() {
                format!("{:.5}", r.value)
            } else {
                "NaN".to_string()
            };
            let opt = |o: Option<usize>| o.map_or(String::new(), |v| v.to_string());
            let _ = writeln!(
                s,
                "{},{},{},{v},{},{},{},{}",
                r.subject,
                r.phase,
                r.measure,
                r.unit,
                opt(r.first_row),
                opt(r.last_row),
                r.source
            );
        }
        s
    }
}

/// A rigid body's positions and quaternions ([x, y, z, w]) per row.
struct Body {
    pos: Vec<Vec3>,
    quat: Vec<[f64; 4]>,
}

fn read_body(dir: &Path, name: &str) -> Res<Body> {
    let path = dir.join(format!("{name}_pose_saved.csv"));
    let mut rd = csv::Reader::from_path(&path)?;
    let header: Vec<String> = rd.headers()?.iter().map(str::to_string).collect();
    if header != ["x", "y", "z", "q0", "q1", "q2", "q3"] {
        return Err(format!("{}: unexpected header {header:?}", path.display()).into());
    }
    let mut pos = Vec::new();
    let mut quat = Vec::new();
    for (i, rec) in rd.records().enumerate() {
        let rec = rec?;
        let f: Vec<f64> = rec
            .iter()
            .map(str::parse::<f64>)
            .collect::<Result<_, _>>()
            .map_err(|e| format!("{} line {}: {e}", path.display(), i + 2))?;
        if f.len() != 7 || f.iter().any(|v| !v.is_finite()) {
            return Err(format!("{} line {}: not 7 finite numbers", path.display(), i + 2).into());
        }
        pos.push(Vec3::new(f[0], f[1], f[2]));
        quat.push([f[3], f[4], f[5], f[6]]);
    }
    Ok(Body { pos, quat })
}

fn read_force(dir: &Path, name: &str) -> Res<Vec<f64>> {
    let path = dir.join(format!("Wrench_{name}_saved.csv"));
    let mut rd = csv::Reader::from_path(&path)?;
    let mut out = Vec::new();
    for rec in rd.records() {
        let rec = rec?;
        let f: Vec<f64> = rec
            .iter()
            .take(3)
            .map(str::parse::<f64>)
            .collect::<Result<_, _>>()?;
        out.push(Vec3::new(f[0], f[1], f[2]).norm());
    }
    Ok(out)
}

/// Centred-difference speed over ±h rows, truncated at the ends [m/s].
fn speed(pos: &[Vec3], h: usize) -> Vec<f64> {
    let n = pos.len();
    (0..n)
        .map(|k| {
            let a = k.saturating_sub(h);
            let b = (k + h).min(n - 1);
            (pos[b] - pos[a]).norm() / ((b - a) as f64 / KTH_RATE_HZ)
        })
        .collect()
}

fn argmax(v: &[f64], from: usize, to: usize) -> usize {
    (from..to).fold(from, |m, k| if v[k] > v[m] { k } else { m })
}

/// The maximal run [start, end) of rows with v ≥ th that contains `peak`.
fn run_around(v: &[f64], peak: usize, th: f64) -> (usize, usize) {
    let mut s = peak;
    while s > 0 && v[s - 1] >= th {
        s -= 1;
    }
    let mut e = peak + 1;
    while e < v.len() && v[e] >= th {
        e += 1;
    }
    (s, e)
}

fn quantile(v: &[f64], q: f64) -> f64 {
    let mut s: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    if s.is_empty() {
        return f64::NAN;
    }
    s.sort_by(f64::total_cmp);
    let r = q * (s.len() - 1) as f64;
    let i = r.floor() as usize;
    let j = (i + 1).min(s.len() - 1);
    s[i] + (s[j] - s[i]) * (r - i as f64)
}

/// Per-axis median of a set of points.
fn quantile_vec(p: &[Vec3]) -> Vec3 {
    let axis = |a: usize| quantile(&p.iter().map(|v| v[a]).collect::<Vec<_>>(), 0.5);
    Vec3::new(axis(0), axis(1), axis(2))
}

/// Residuals of a linear least-squares fit against the index.
fn detrend(x: &[f64]) -> Vec<f64> {
    let n = x.len() as f64;
    let tm = (n - 1.0) / 2.0;
    let xm = mean(x);
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for (i, v) in x.iter().enumerate() {
        let t = i as f64 - tm;
        sxy += t * (v - xm);
        sxx += t * t;
    }
    let b = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    x.iter()
        .enumerate()
        .map(|(i, v)| v - xm - b * (i as f64 - tm))
        .collect()
}

fn sd(x: &[f64]) -> f64 {
    let m = mean(x);
    (x.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / (x.len() as f64 - 1.0)).sqrt()
}

fn lag1(r: &[f64]) -> f64 {
    let m = mean(r);
    let c0: f64 = r.iter().map(|v| (v - m) * (v - m)).sum();
    let c1: f64 = r.windows(2).map(|w| (w[0] - m) * (w[1] - m)).sum();
    c1 / c0
}

/// Jitter statistics of a 3-axis series (at whatever rate it is given): σ axis-RMS after a
/// linear detrend, σ from first differences (axis-RMS of std(Δx)/√2), mean lag-1
/// autocorrelation of the detrended residual.
fn jitter(series: &[[f64; 3]]) -> (f64, f64, f64) {
    if series.len() < 4 {
        return (f64::NAN, f64::NAN, f64::NAN);
    }
    let (mut s2, mut d2, mut l) = (0.0, 0.0, 0.0);
    for a in 0..3 {
        let x: Vec<f64> = series.iter().map(|p| p[a]).collect();
        let r = detrend(&x);
        s2 += sd(&r).powi(2);
        let d: Vec<f64> = x.windows(2).map(|w| w[1] - w[0]).collect();
        d2 += sd(&d).powi(2) / 2.0;
        l += lag1(&r);
    }
    ((s2 / 3.0).sqrt(), (d2 / 3.0).sqrt(), l / 3.0)
}

/// The §7 filtered speed per 30 Hz frame (None on the first frame).
fn filtered_speed(frames: &[Vec3], dt: f64) -> Vec<Option<f64>> {
    let mut f = OneEuro3::new(OneEuroConfig::default());
    let mut out = Vec::with_capacity(frames.len());
    for (i, p) in frames.iter().enumerate() {
        if i == 0 {
            f.filter((*p).into(), 0.0);
            out.push(None);
        } else {
            let before = Vec3::from(f.value());
            let after = Vec3::from(f.filter((*p).into(), dt));
            out.push(Some((after - before).norm() / dt));
        }
    }
    out
}

/// SplitMix64 with a Box–Muller Gaussian (deterministic simulated checks).
struct SplitMix64(u64);

impl SplitMix64 {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }
    fn gaussian(&mut self) -> f64 {
        let u1 = self.uniform().max(1e-300);
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
    fn gauss3(&mut self) -> Vec3 {
        Vec3::new(self.gaussian(), self.gaussian(), self.gaussian())
    }
}

/// The filtered speed of a still point with iid Gaussian noise σ per axis at 30 Hz [m/s], after
/// 0.5 s of warm-up.
fn iid_still_speeds(sigma: f64, seed: u64) -> Vec<f64> {
    let mut rng = SplitMix64(seed);
    let x: Vec<Vec3> = (0..SIM_FRAMES).map(|_| rng.gauss3() * sigma).collect();
    filtered_speed(&x, 1.0 / 30.0)
        .into_iter()
        .skip(15)
        .flatten()
        .collect()
}

/// Median and p90 of [`iid_still_speeds`] [m/s].
fn iid_still_speed(sigma: f64, seed: u64) -> (f64, f64) {
    let v = iid_still_speeds(sigma, seed);
    (quantile(&v, 0.5), quantile(&v, 0.9))
}

/// Share of frames below v_min, and share of 9-frame windows (t_min = 0.3 s at 30 Hz) whose
/// every frame is below v_min [-].
fn below_vmin_shares(v: &[f64]) -> (f64, f64) {
    let b: Vec<bool> = v.iter().map(|x| *x < V_MIN).collect();
    let frames = b.iter().filter(|x| **x).count() as f64 / b.len() as f64;
    let windows =
        b.windows(9).filter(|w| w.iter().all(|x| *x)).count() as f64 / (b.len() - 8) as f64;
    (frames, windows)
}

/// A phase of one hand: rows [start, end).
#[derive(Clone, Copy)]
struct Span {
    name: &'static str,
    start: usize,
    end: usize,
}

/// What the analysis of one hand returns for the figure.
struct HandResult {
    label: &'static str,
    speed: Vec<f64>,
    spans: Vec<Span>,
    dist: Vec<f64>,
}

#[allow(clippy::too_many_arguments)]
fn phase_stats(
    out: &mut Out,
    subject: &str,
    span: Span,
    pos: &[Vec3],
    v: &[f64],
    v_short: &[f64],
    vh: &[Option<f64>],
) {
    let (s, e) = (span.start, span.end);
    let sp = Some((s, e));
    let src = "kth";
    let dt = 1.0 / KTH_RATE_HZ;
    let p = span.name;
    out.push(subject, p, "start", s as f64 * dt, "s", sp, src);
    out.push(subject, p, "end", e as f64 * dt, "s", sp, src);
    out.push(subject, p, "duration", (e - s) as f64 * dt, "s", sp, src);
    if e <= s + 1 {
        return;
    }
    let vv = &v[s..e];
    let path: f64 = vv.iter().sum::<f64>() * dt;
    out.push(subject, p, "path_length", path, "m", sp, src);
    let net = (pos[e - 1] - pos[s]).norm();
    out.push(subject, p, "net_displacement", net, "m", sp, src);
    let k = argmax(v, s, e);
    out.push(subject, p, "peak_speed", v[k], "m/s", sp, src);
    out.push(subject, p, "peak_time", k as f64 * dt, "s", sp, src);
    out.push(
        subject,
        p,
        "peak_time_fraction",
        (k - s) as f64 / (e - s) as f64,
        "-",
        sp,
        src,
    );
    let ks = argmax(v_short, s, e);
    out.push(subject, p, "peak_speed_h3", v_short[ks], "m/s", sp, src);
    let m = mean(vv);
    out.push(subject, p, "mean_speed", m, "m/s", sp, src);
    out.push(subject, p, "peak_over_mean", v[k] / m, "-", sp, src);
    out.push(
        subject,
        p,
        "net_over_duration",
        net / ((e - s) as f64 * dt),
        "m/s",
        sp,
        src,
    );
    out.push(subject, p, "speed_p10", quantile(vv, 0.1), "m/s", sp, src);
    out.push(
        subject,
        p,
        "speed_median",
        quantile(vv, 0.5),
        "m/s",
        sp,
        src,
    );
    out.push(subject, p, "speed_p90", quantile(vv, 0.9), "m/s", sp, src);
    let share = |th: f64| vv.iter().filter(|x| **x < th).count() as f64 / vv.len() as f64;
    out.push(subject, p, "share_below_0.03", share(V_MIN), "-", sp, src);
    out.push(subject, p, "share_below_0.10", share(V_MOVE), "-", sp, src);
    // 30 Hz: jitter and the §7 filtered speed.
    let frames: Vec<usize> = (s..e).filter(|r| r % DECIMATE == 0).collect();
    let series: Vec<[f64; 3]> = frames.iter().map(|&r| pos[r].into()).collect();
    let (sig, sig_d, l1) = jitter(&series);
    let src30 = "kth_30hz";
    out.push(subject, p, "sd_axis_rms_30hz", sig, "m", sp, src30);
    out.push(subject, p, "sd_diff_30hz", sig_d, "m", sp, src30);
    out.push(subject, p, "lag1_30hz", l1, "-", sp, src30);
    let warm = (WARMUP_S * KTH_RATE_HZ).round() as usize;
    let h: Vec<f64> = frames
        .iter()
        .filter(|&&r| r >= warm)
        .filter_map(|&r| vh[r / DECIMATE])
        .collect();
    if !h.is_empty() {
        out.push(
            subject,
            p,
            "vh_median_30hz",
            quantile(&h, 0.5),
            "m/s",
            sp,
            src30,
        );
        out.push(
            subject,
            p,
            "vh_p90_30hz",
            quantile(&h, 0.9),
            "m/s",
            sp,
            src30,
        );
        out.push(
            subject,
            p,
            "vh_max_30hz",
            quantile(&h, 1.0),
            "m/s",
            sp,
            src30,
        );
        let below = h.iter().filter(|x| **x < V_MIN).count() as f64 / h.len() as f64;
        out.push(subject, p, "vh_share_below_vmin", below, "-", sp, src30);
    }
}

fn near_stats(out: &mut Out, subject: &str, dist: &[f64], v: &[f64], grasp: usize) {
    for (r, name) in [(0.05, "near_5cm"), (0.10, "near_10cm")] {
        let mut s = grasp;
        while s > 0 && dist[s - 1] <= r {
            s -= 1;
        }
        let mut e = grasp + 1;
        while e < dist.len() && dist[e] <= r {
            e += 1;
        }
        let sp = Some((s, e));
        let dt = 1.0 / KTH_RATE_HZ;
        let vv = &v[s..e];
        let src = "kth";
        out.push(subject, name, "entry", s as f64 * dt, "s", sp, src);
        out.push(subject, name, "exit", e as f64 * dt, "s", sp, src);
        out.push(subject, name, "duration", (e - s) as f64 * dt, "s", sp, src);
        out.push(subject, name, "entry_speed", v[s], "m/s", sp, src);
        out.push(
            subject,
            name,
            "exit_speed",
            v[e.min(v.len() - 1)],
            "m/s",
            sp,
            src,
        );
        out.push(subject, name, "speed_mean", mean(vv), "m/s", sp, src);
        out.push(
            subject,
            name,
            "speed_median",
            quantile(vv, 0.5),
            "m/s",
            sp,
            src,
        );
        out.push(
            subject,
            name,
            "speed_min",
            quantile(vv, 0.0),
            "m/s",
            sp,
            src,
        );
        out.push(
            subject,
            name,
            "speed_max",
            quantile(vv, 1.0),
            "m/s",
            sp,
            src,
        );
    }
}

/// The grasp row of the giver's regrasp: the first row after its |F| fell below 1 N where it
/// exceeds 5 N again.
fn regrasp_row(f: &[f64]) -> Option<usize> {
    let low = f.iter().position(|x| *x < 1.0)?;
    (low..f.len()).find(|&k| f[k] > 5.0)
}

#[allow(clippy::too_many_arguments)]
fn analyse_hand(
    out: &mut Out,
    subject: &'static str,
    label: &'static str,
    pos: &[Vec3],
    search_from: usize,
    grasp: usize,
    release: usize,
    names: [&'static str; 5],
) -> HandResult {
    let v = speed(pos, HALF_WINDOW);
    let v_short = speed(pos, HALF_WINDOW_SHORT);
    let n = pos.len();
    let peak = argmax(&v, search_from, grasp);
    let (a_s, a_e) = run_around(&v, peak, V_MOVE);
    let a_e = a_e.min(release);
    let peak2 = argmax(&v, release, n);
    let d_e = run_around(&v, peak2, V_MOVE).1;
    let spans = vec![
        Span {
            name: names[0],
            start: 0,
            end: a_s,
        },
        Span {
            name: names[1],
            start: a_s,
            end: a_e,
        },
        Span {
            name: names[2],
            start: a_e,
            end: release,
        },
        Span {
            name: names[3],
            start: release,
            end: d_e,
        },
        Span {
            name: names[4],
            start: d_e,
            end: n,
        },
    ];
    let frames: Vec<Vec3> = pos.iter().step_by(DECIMATE).copied().collect();
    let vh = filtered_speed(&frames, DECIMATE as f64 / KTH_RATE_HZ);
    for s in &spans {
        phase_stats(out, subject, *s, pos, &v, &v_short, &vh);
    }
    let point = pos[grasp];
    let dist: Vec<f64> = pos.iter().map(|p| (p - point).norm()).collect();
    near_stats(out, subject, &dist, &v, grasp);
    HandResult {
        label,
        speed: v,
        spans,
        dist,
    }
}

/// Head facing angles (two, about the mean direction) per 30 Hz frame of rows [s, e) [rad].
fn facing_angles(q: &[[f64; 4]], s: usize, e: usize) -> Vec<[f64; 2]> {
    let dirs: Vec<Vec3> = (s..e)
        .filter(|r| r % DECIMATE == 0)
        .filter_map(|r| rotate_xyzw(q[r], assess::io::kth::FACING_AXIS))
        .collect();
    let m = dirs.iter().fold(Vec3::zeros(), |a, d| a + d).normalize();
    let u = m.cross(&Vec3::z()).normalize();
    let w = m.cross(&u);
    dirs.iter()
        .map(|d| [d.dot(&u).atan2(d.dot(&m)), d.dot(&w).atan2(d.dot(&m))])
        .collect()
}

fn main() -> Res<()> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let out_dir = std::env::args()
        .nth(1)
        .map_or_else(|| root.join("docs/calibration"), PathBuf::from);
    let kth = std::env::args().nth(2).map_or_else(
        || root.join("data/human-motion/kth-handover"),
        PathBuf::from,
    );

    let rec = read_recording(&kth, &KthOptions::default())?;
    let row = |t: Option<f64>| t.map(|t| (t * KTH_RATE_HZ).round() as usize);
    let (onset, grasp, release) = match (
        row(rec.events.reach_onset_s),
        row(rec.events.grasp_s),
        row(rec.events.release_s),
    ) {
        (Some(o), Some(g), Some(r)) => (o, g, r),
        _ => return Err("the recording's handover events were not found".into()),
    };
    let taker = read_body(&kth, "taker_RHand")?;
    let giver = read_body(&kth, "giver_RHand")?;
    let giver_f = read_force(&kth, "giver")?;
    let regrasp = regrasp_row(&giver_f).ok_or("no giver regrasp")?;

    let mut out = Out::default();
    let ev = "kth_events";
    let dt = 1.0 / KTH_RATE_HZ;
    out.push(
        "events",
        "-",
        "baton_reach_onset",
        onset as f64 * dt,
        "s",
        None,
        ev,
    );
    out.push(
        "events",
        "-",
        "giver_regrasp",
        regrasp as f64 * dt,
        "s",
        None,
        ev,
    );
    out.push("events", "-", "grasp", grasp as f64 * dt, "s", None, ev);
    out.push("events", "-", "release", release as f64 * dt, "s", None, ev);

    let t = analyse_hand(
        &mut out,
        "taker_right",
        "Taker right hand",
        &taker.pos,
        0,
        grasp,
        release,
        ["rest", "reach", "hold", "transport", "rest_after"],
    );
    let g = analyse_hand(
        &mut out,
        "giver_right",
        "Giver right hand",
        &giver.pos,
        regrasp,
        grasp,
        release,
        ["preparation", "transport", "hold", "withdraw", "rest_after"],
    );

    // Taker head and chest while the taker's hand rests (physiological sway, 30 Hz).
    let rest = t.spans[0];
    let warm = (WARMUP_S * KTH_RATE_HZ).round() as usize;
    for (name, body) in [("taker_head", "taker_head"), ("taker_chest", "taker_chest")] {
        let b = read_body(&kth, body)?;
        let series: Vec<[f64; 3]> = (rest.start..rest.end)
            .filter(|r| r % DECIMATE == 0)
            .map(|r| b.pos[r].into())
            .collect();
        let (s, sd_, l) = jitter(&series);
        let sp = Some((rest.start, rest.end));
        out.push(name, "rest", "sd_axis_rms_30hz", s, "m", sp, "kth_30hz");
        out.push(name, "rest", "sd_diff_30hz", sd_, "m", sp, "kth_30hz");
        out.push(name, "rest", "lag1_30hz", l, "-", sp, "kth_30hz");
        if name == "taker_head" {
            let a = facing_angles(&b.quat, rest.start, rest.end);
            let mut sig = 0.0;
            let mut lg = 0.0;
            for c in 0..2 {
                let x: Vec<f64> = a.iter().map(|v| v[c]).collect();
                let r = detrend(&x);
                sig += sd(&r).powi(2) / 2.0;
                lg += lag1(&r) / 2.0;
            }
            out.push(
                name,
                "rest",
                "facing_sd_rms_30hz",
                sig.sqrt(),
                "rad",
                sp,
                "kth_30hz",
            );
            out.push(name, "rest", "facing_lag1_30hz", lg, "-", sp, "kth_30hz");
        }
    }

    // Taker anthropometry (rigid-body origins sit at the proximal joints: upper arm at the
    // shoulder, forearm at the elbow, hand at the wrist) and head turning speed.
    {
        let b = |n: &str| read_body(&kth, n);
        let (head, chest) = (b("taker_head")?, b("taker_chest")?);
        let (lu, ru, rf) = (b("taker_LUArm")?, b("taker_RUArm")?, b("taker_RFArm")?);
        let n = taker.pos.len();
        let med = |f: &dyn Fn(usize) -> f64| quantile(&(0..n).map(f).collect::<Vec<_>>(), 0.5);
        let sub = "taker_body";
        let src = "kth";
        let mid = |k: usize| (lu.pos[k] + ru.pos[k]) / 2.0;
        out.push(
            sub,
            "all",
            "head_minus_shoulder_z_median",
            med(&|k| head.pos[k].z - mid(k).z),
            "m",
            None,
            src,
        );
        out.push(
            sub,
            "all",
            "shoulder_minus_chest_z_median",
            med(&|k| mid(k).z - chest.pos[k].z),
            "m",
            None,
            src,
        );
        out.push(
            sub,
            "all",
            "shoulder_width_median",
            med(&|k| (lu.pos[k] - ru.pos[k]).norm()),
            "m",
            None,
            src,
        );
        out.push(
            sub,
            "all",
            "upper_arm_median",
            med(&|k| (rf.pos[k] - ru.pos[k]).norm()),
            "m",
            None,
            src,
        );
        out.push(
            sub,
            "all",
            "forearm_median",
            med(&|k| (taker.pos[k] - rf.pos[k]).norm()),
            "m",
            None,
            src,
        );
        let sw: Vec<f64> = (0..n).map(|k| (taker.pos[k] - ru.pos[k]).norm()).collect();
        out.push(
            sub,
            "all",
            "shoulder_to_wrist_max",
            quantile(&sw, 1.0),
            "m",
            None,
            src,
        );
        out.push(
            sub,
            "grasp",
            "shoulder_to_wrist",
            sw[grasp],
            "m",
            Some((grasp, grasp + 1)),
            src,
        );
        out.push(
            sub,
            "rest",
            "shoulder_to_wrist_median",
            quantile(&sw[rest.start..rest.end], 0.5),
            "m",
            Some((rest.start, rest.end)),
            src,
        );
        let ch = (chest.pos[grasp] - quantile_vec(&chest.pos[rest.start..rest.end])).norm();
        out.push(
            sub,
            "grasp",
            "chest_displacement_from_rest",
            ch,
            "m",
            Some((grasp, grasp + 1)),
            src,
        );
        let sh = (ru.pos[grasp] - quantile_vec(&ru.pos[rest.start..rest.end])).norm();
        out.push(
            sub,
            "grasp",
            "shoulder_displacement_from_rest",
            sh,
            "m",
            Some((grasp, grasp + 1)),
            src,
        );
        // Head facing angular speed, centred difference over ±HALF_WINDOW rows [rad/s].
        let f: Vec<Vec3> = head
            .quat
            .iter()
            .map(|q| rotate_xyzw(*q, assess::io::kth::FACING_AXIS).unwrap_or(Vec3::zeros()))
            .collect();
        let w: Vec<f64> = (0..n)
            .map(|k| {
                let a = k.saturating_sub(HALF_WINDOW);
                let e = (k + HALF_WINDOW).min(n - 1);
                f[a].angle(&f[e]) / ((e - a) as f64 / KTH_RATE_HZ)
            })
            .collect();
        out.push(
            "taker_head",
            "all",
            "facing_angular_speed_peak",
            quantile(&w, 1.0),
            "rad/s",
            None,
            src,
        );
        out.push(
            "taker_head",
            "all",
            "facing_angular_speed_p90",
            quantile(&w, 0.9),
            "rad/s",
            None,
            src,
        );
        out.push(
            "taker_head",
            "all",
            "facing_angular_speed_median",
            quantile(&w, 0.5),
            "rad/s",
            None,
            src,
        );
    }

    // SIMULATED checks of the operator's noise and motion constants.
    let sim = "simulated";
    for (i, mm) in [0.5, 0.84, 1.0, 1.5, 2.0, 2.2, 2.5, 3.0, 3.5, 5.0]
        .iter()
        .enumerate()
    {
        let v = iid_still_speeds(mm * 1e-3, 0x14_0001 + i as u64);
        let ph = format!("iid_sigma_{mm}mm");
        out.push(
            "model",
            &ph,
            "vh_median_30hz",
            quantile(&v, 0.5),
            "m/s",
            None,
            sim,
        );
        out.push(
            "model",
            &ph,
            "vh_p90_30hz",
            quantile(&v, 0.9),
            "m/s",
            None,
            sim,
        );
        let (f, w) = below_vmin_shares(&v);
        out.push("model", &ph, "vh_share_below_vmin", f, "-", None, sim);
        out.push(
            "model",
            &ph,
            "share_9frame_runs_below_vmin",
            w,
            "-",
            None,
            sim,
        );
    }
    // The real resting hand (taker, 30 Hz) plus the measured perception noise.
    {
        let mut rng = SplitMix64(0x14_0100);
        let frames: Vec<Vec3> = (0..taker.pos.len())
            .step_by(DECIMATE)
            .map(|r| taker.pos[r] + rng.gauss3() * PERCEPTION_HAND_SIGMA_M)
            .collect();
        let vh = filtered_speed(&frames, DECIMATE as f64 / KTH_RATE_HZ);
        let h: Vec<f64> = (rest.start..rest.end)
            .filter(|r| r % DECIMATE == 0 && *r >= warm)
            .filter_map(|r| vh[r / DECIMATE])
            .collect();
        let ph = "kth_rest_plus_perception";
        let sp = Some((rest.start, rest.end));
        out.push(
            "model",
            ph,
            "vh_median_30hz",
            quantile(&h, 0.5),
            "m/s",
            sp,
            sim,
        );
        out.push(
            "model",
            ph,
            "vh_p90_30hz",
            quantile(&h, 0.9),
            "m/s",
            sp,
            sim,
        );
        // The iid σ whose median v_h matches this (bisection on the simulated curve).
        let target = quantile(&h, 0.5);
        let (mut lo, mut hi) = (1e-4_f64, 1e-2_f64);
        for _ in 0..30 {
            let mid = (lo * hi).sqrt();
            if iid_still_speed(mid, 0x14_0200).0 < target {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let sigma = (lo * hi).sqrt();
        out.push("model", ph, "equivalent_iid_sigma", sigma, "m", sp, sim);
        let (m, p) = iid_still_speed(sigma, 0x14_0201);
        out.push("model", ph, "equivalent_iid_vh_median", m, "m/s", sp, sim);
        out.push("model", ph, "equivalent_iid_vh_p90", p, "m/s", sp, sim);
    }
    // The operator's working motion (circle of radius r at f Hz, z = 0.3 r sin 2ωt), noise-free,
    // at 30 Hz through the §7 filter.
    for (r, f) in [(0.02, 1.0), (0.02, 1.5), (0.03, 1.0), (0.025, 1.2)] {
        let w = std::f64::consts::TAU * f;
        let frames: Vec<Vec3> = (0..3000)
            .map(|k| {
                let t = k as f64 / 30.0;
                Vec3::new((w * t).cos(), (w * t).sin(), 0.3 * (2.0 * w * t).sin()) * r
            })
            .collect();
        let raw: Vec<f64> = frames
            .windows(2)
            .map(|p| (p[1] - p[0]).norm() * 30.0)
            .collect();
        let vh: Vec<f64> = filtered_speed(&frames, 1.0 / 30.0)
            .into_iter()
            .skip(60)
            .flatten()
            .collect();
        let ph = format!("work_motion_r{r}_f{f}");
        out.push("model", &ph, "raw_speed_mean", mean(&raw), "m/s", None, sim);
        out.push(
            "model",
            &ph,
            "vh_median_30hz",
            quantile(&vh, 0.5),
            "m/s",
            None,
            sim,
        );
        out.push(
            "model",
            &ph,
            "vh_p10_30hz",
            quantile(&vh, 0.1),
            "m/s",
            None,
            sim,
        );
    }

    std::fs::create_dir_all(&out_dir)?;
    let csv_path = out_dir.join("kth_kinematics.csv");
    std::fs::write(&csv_path, out.csv())?;
    let png_path = out_dir.join("kth_kinematics.png");
    figure(&png_path, &[&t, &g], grasp, release)?;
    println!("wrote {} ({} rows)", csv_path.display(), out.rows.len());
    println!("wrote {}", png_path.display());
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// The figure (plotters, with the DejaVu Sans font the root crate embeds).

/// The font family the embedded font is registered under (as in `src/report/plot.rs`).
const FAMILY: &str = "sans-serif";
/// The root crate's embedded font (`src/report/plot.rs`), so no system font is needed.
static FONT_BYTES: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");
/// Pixel size of the figure (width, height).
const FIGURE_PX: (u32, u32) = (1400, 1080);

const TAKER_BLUE: RGBColor = RGBColor(20, 40, 140);
const GIVER_ORANGE: RGBColor = RGBColor(170, 60, 0);
const GRASP_RED: RGBColor = RGBColor(200, 30, 30);
const RELEASE_GREEN: RGBColor = RGBColor(20, 130, 40);
const LABEL_GREY: RGBColor = RGBColor(90, 90, 90);

fn font(size: u32) -> TextStyle<'static> {
    (FAMILY, size).into_font().color(&BLACK)
}

/// The embedded font in colour `c`, anchored at `pos`.
fn text_style(size: u32, c: RGBColor, pos: Pos) -> TextStyle<'static> {
    let mut style = font(size);
    style.color = c.to_backend_color();
    style.pos = pos;
    style
}

fn phase_colour(name: &str) -> RGBColor {
    match name {
        "reach" => RGBColor(200, 220, 255),
        "hold" => RGBColor(255, 222, 170),
        "transport" => RGBColor(205, 240, 205),
        "withdraw" => RGBColor(235, 210, 245),
        "preparation" => RGBColor(240, 240, 200),
        _ => RGBColor(232, 232, 232),
    }
}

/// A dashed straight line from `a` to `b` (data coordinates).
fn dashed(
    a: (f64, f64),
    b: (f64, f64),
    c: RGBColor,
    width: u32,
) -> DashedLineSeries<std::array::IntoIter<(f64, f64), 2>, i32> {
    DashedLineSeries::new([a, b], 8, 6, c.stroke_width(width))
}

/// Three panels: taker speed, giver speed (phases shaded), distance to each hand's handover
/// point; written to `path` as PNG.
fn figure(path: &Path, hands: &[&HandResult], grasp: usize, release: usize) -> Res<()> {
    plotters::style::register_font(FAMILY, FontStyle::Normal, FONT_BYTES)
        .map_err(|_| "the embedded font assets/fonts/DejaVuSans.ttf could not be loaded")?;
    let n = hands[0].speed.len();
    let t = |k: usize| k as f64 / KTH_RATE_HZ;
    let t_max = t(n - 1);
    let root = BitMapBackend::new(path, FIGURE_PX).into_drawing_area();
    root.fill(&WHITE)?;
    let root = root.titled(
        "KTH handover, the real recording (OptiTrack, 120 Hz): right-hand speed, centred \
         difference ±50 ms",
        font(22),
    )?;
    let panels = root.split_evenly((3, 1));
    let right = |pos: VPos| Pos::new(HPos::Right, pos);
    for (pi, area) in panels.iter().enumerate() {
        let (caption, y_max, y_desc) = if pi < 2 {
            (hands[pi].label, 1.4, "speed |v| [m/s]")
        } else {
            (
                "Distance of each hand to its own position at the grasp",
                0.7,
                "distance [m]",
            )
        };
        let mut chart = ChartBuilder::on(area)
            .caption(caption, font(18))
            .margin(6)
            .margin_right(24)
            .x_label_area_size(44)
            .y_label_area_size(72)
            .build_cartesian_2d(0.0..t_max, 0.0..y_max)?;
        if pi < 2 {
            // The phases, shaded and named (under the grid).
            let spans = &hands[pi].spans;
            chart.draw_series(spans.iter().map(|s| {
                let (a, b) = (t(s.start), t(s.end).min(t_max));
                Rectangle::new([(a, 0.0), (b, y_max)], phase_colour(s.name).filled())
            }))?;
            chart.draw_series(spans.iter().map(|s| {
                let mid = (t(s.start) + t(s.end).min(t_max)) / 2.0;
                let style = text_style(13, LABEL_GREY, Pos::new(HPos::Center, VPos::Top));
                Text::new(s.name.replace('_', " "), (mid, 0.98 * y_max), style)
            }))?;
        }
        chart
            .configure_mesh()
            .x_desc("time t [s]")
            .y_desc(y_desc)
            .axis_desc_style(font(16))
            .label_style(font(14))
            .x_labels(14)
            .y_labels(8)
            .light_line_style(TRANSPARENT)
            .bold_line_style(BLACK.mix(0.12))
            .axis_style(BLACK.mix(0.8))
            .draw()?;
        let label = |text: &str, at: (f64, f64), c: RGBColor, pos: Pos| {
            Text::new(text.to_string(), at, text_style(13, c, pos))
        };
        // The force events.
        for (row, c, name) in [
            (grasp, GRASP_RED, "grasp"),
            (release, RELEASE_GREEN, "release"),
        ] {
            chart.draw_series(dashed((t(row), 0.0), (t(row), y_max), c, 2))?;
            let pos = if row == grasp {
                right(VPos::Bottom)
            } else {
                Pos::new(HPos::Left, VPos::Bottom)
            };
            let x = t(row) + if row == grasp { -0.02 } else { 0.02 };
            chart.draw_series([label(name, (x, 0.01 * y_max), c, pos)])?;
        }
        if pi < 2 {
            let sp = &hands[pi].speed;
            chart
                .draw_series(LineSeries::new(
                    (0..n).map(|k| (t(k), sp[k])),
                    TAKER_BLUE.stroke_width(2),
                ))?
                .label("speed |v| of the right hand")
                .legend(|(x, y)| {
                    PathElement::new(vec![(x, y), (x + 24, y)], TAKER_BLUE.stroke_width(3))
                });
            for (v, c, text) in [
                (V_MOVE, GRASP_RED, "v_move = v_max = 0.10 m/s"),
                (V_MIN, LABEL_GREY, "v_min = 0.03 m/s"),
            ] {
                chart
                    .draw_series(dashed((0.0, v), (t_max, v), c, 1))?
                    .label(text)
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 24, y)], c.stroke_width(1))
                    });
            }
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::Coordinate(12, 34))
                .label_font(font(14))
                .background_style(WHITE.mix(0.9))
                .border_style(BLACK.mix(0.3))
                .draw()?;
        } else {
            for (r, text) in [(0.05, "5 cm"), (0.10, "10 cm")] {
                chart.draw_series(dashed((0.0, r), (t_max, r), LABEL_GREY, 1))?;
                chart.draw_series([label(
                    text,
                    (t_max, r + 0.004),
                    LABEL_GREY,
                    right(VPos::Bottom),
                )])?;
            }
            for (hi, c, name) in [(0, TAKER_BLUE, "taker"), (1, GIVER_ORANGE, "giver")] {
                let d = &hands[hi].dist;
                chart
                    .draw_series(LineSeries::new(
                        (0..n).map(|k| (t(k), d[k])),
                        c.stroke_width(2),
                    ))?
                    .label(format!("{name} right hand"))
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 24, y)], c.stroke_width(3))
                    });
            }
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::UpperMiddle)
                .label_font(font(15))
                .background_style(WHITE.mix(0.9))
                .border_style(BLACK.mix(0.3))
                .draw()?;
        }
    }
    root.present()?;
    Ok(())
}
