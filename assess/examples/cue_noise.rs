//! Issue 14, point 1 (measurement only): the jitter of the perception pipeline's own cues on
//! still and slowly panned video made from the bundled photos, with and without depth, to fit
//! the simulated operator's noise (`src/trial/operator.rs`, `COMMON`) to it later.
//!
//! What is real and what is SIMULATED:
//! - the photos (`data/images/`) are real;
//! - the motion is SIMULATED: each photo is scaled into a 640 × 480 frame with `moving.rs`'s
//!   bilinear warp and either left still or panned right by [`PAN_PX_PER_FRAME`] per frame
//!   (sub-pixel, linear in time), [`FRAMES`] frames at 30 Hz;
//! - the RGB sensor noise is SIMULATED (an ASSUMPTION, see [`READ_NOISE_DN`]): per pixel and
//!   channel, independent Gaussian with variance σ_read² + g·v (read noise plus shot noise, the
//!   photon-transfer model of EMVA 1288), σ_read = 1.5 DN and g = 0.035 DN (σ ≈ 3.3 DN at
//!   v = 255), from a fixed-seed SplitMix64, on top of whatever noise the photo already has
//!   (which is the same on every frame);
//! - the depth is SIMULATED: a fronto-parallel plane at the head's PnP distance on the first
//!   frame (0.6 m when the photo has no face), with the canonical face model rendered into it at
//!   that first-frame PnP pose (moved with the pan), plus D435-like noise: independent Gaussian
//!   per pixel with the RMS error of Intel's D400 white paper, σ_z = z² · s / (f · B), subpixel
//!   s = 0.08, baseline B = 50 mm, depth focal length f = 447 px (848 × 480, 87° HFOV), rounded
//!   to the 1 mm depth unit. Real depth noise is spatially correlated; independent pixel noise
//!   is the optimistic case for the cue extraction's median patches.
//!
//! For each photo × motion × depth/no-depth it runs [`Pipeline`] in tracking mode (default full
//! models) and [`CueExtractor::extract`] as `perception.rs` does (identity extrinsics: the
//! workspace frame is the camera frame, x right, y down, z forward), skips the first
//! [`SETTLE`] frames and reports per cue (head/torso position and facing, each hand's
//! position): the standard deviation per axis after a linear detrend, the per-axis RMS of
//! those, the same from first differences (std(Δx)/√2, equal to the former for white noise),
//! the lag-1 autocorrelation of the detrended residual, the cue confidence and landmark score,
//! and for hands the §7 filtered speed v_h (One-Euro, the `[hesitation.one_euro]` defaults) of
//! the measured positions. Facing angles are the two angles [rad] of the facing vector about
//! the series' mean direction. Rows `simulator` run the operator's own noise model (iid
//! Gaussian 0.005 m per axis; 0.04 rad via `noisy_direction`) through the same statistics.
//!
//! Run with `cargo run --release -p assess --features vision --example cue_noise -- [out.csv]`
//! (default `docs/calibration/cue_noise.csv`; after `scripts/setup`; `source
//! scripts/deps/env.sh` for ONNX Runtime).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use assess::filter::OneEuro3;
use assess::vision::cues::{CueConfig, CueExtractor, PerceivedCues, load_canonical_face, pnp};
use assess::vision::pipeline::{Mode, Pipeline, PipelineConfig};
use assess::vision::{DepthImage, Extrinsics, Intrinsics, Landmark, Landmarks, RgbImage, models};
use assess::{HesitationConfig, Vec3};
use nalgebra::Point3;

#[allow(dead_code)] // only the warp is used here
#[path = "../tests/support/moving.rs"]
mod moving;
#[allow(dead_code)] // only the PRNG is used here
#[path = "../tests/support/scenes.rs"]
mod scenes;

#[path = "support/stats.rs"]
mod stats;

use scenes::SplitMix64;
use stats::mean;

type Res<T> = Result<T, Box<dyn std::error::Error>>;

/// Frames per video (4 s at 30 Hz).
const FRAMES: usize = 120;
/// Frames skipped at the start of every series (0.5 s: the first detection, and three time
/// constants of the cue extraction's 1 Hz One-Euro filters, which start at the first sample).
const SETTLE: usize = 15;
/// Camera rate [1/s].
const FPS: f64 = 30.0;
/// Slow pan [px/frame] (9 px/s).
const PAN_PX_PER_FRAME: f64 = 0.3;
/// SIMULATED RGB read noise σ_read [DN] (ASSUMPTION: typical of a small CMOS colour sensor in
/// indoor light after the ISP; the D435i's colour sensor has no published noise figures).
const READ_NOISE_DN: f64 = 1.5;
/// SIMULATED RGB shot-noise gain g [DN]: variance g·v at level v [DN] (ASSUMPTION, as above).
const SHOT_GAIN_DN: f64 = 0.035;
/// D400 RMS depth error: subpixel s [px], baseline [m], depth focal length [px] (Intel,
/// "Tuning depth cameras for best performance", D435 at 848 × 480).
const DEPTH_SUBPIXEL: f64 = 0.08;
/// See [`DEPTH_SUBPIXEL`] [m].
const DEPTH_BASELINE_M: f64 = 0.050;
/// See [`DEPTH_SUBPIXEL`] [px].
const DEPTH_FOCAL_PX: f64 = 447.0;
/// Depth unit [m] (the D435i default).
const DEPTH_UNIT_M: f64 = 0.001;
/// Plane depth when the photo shows no face [m].
const DEFAULT_Z_M: f64 = 0.6;
/// Colour camera horizontal field of view [deg] (D435i colour, as `moving_video`).
const HFOV_DEG: f64 = 69.0;

/// The photos: file under `data/images/` and scale into the frame.
/// `pose_sitting.jpg` twice: at `moving.rs`'s scale (head ≈ 1.35 m away) and cropped closer
/// (≈ 1 m); `two_children.jpeg` scaled down so that the face is ≈ 0.6 m away.
const PHOTOS: [(&str, f64); 5] = [
    ("pose_sitting.jpg", 0.75),
    ("pose_sitting.jpg", 1.0),
    ("business-person.png", 0.35),
    ("two_children.jpeg", 0.3),
    ("hand_thumb_up.jpg", 0.85),
];

#[derive(Clone, Copy, PartialEq)]
enum Motion {
    Still,
    Pan,
}

impl Motion {
    fn name(self) -> &'static str {
        match self {
            Motion::Still => "still",
            Motion::Pan => "pan",
        }
    }

    /// Pan of frame `k` [px], centred on the middle frame.
    fn pan(self, k: usize) -> f64 {
        match self {
            Motion::Still => 0.0,
            Motion::Pan => PAN_PX_PER_FRAME * (k as f64 - FRAMES as f64 / 2.0),
        }
    }
}

/// The SIMULATED noisy frames of one photo and motion.
fn frames(src: &RgbImage, scale: f64, motion: Motion, seed: u64) -> Vec<RgbImage> {
    (0..FRAMES)
        .map(|k| {
            let mut f = moving::warp(src, scale, [motion.pan(k), 0.0], 0.0);
            let mut rng = SplitMix64(seed ^ ((k as u64) << 20));
            for v in &mut f.data {
                let x = f64::from(*v);
                let sigma = (READ_NOISE_DN * READ_NOISE_DN + SHOT_GAIN_DN * x).sqrt();
                *v = (x + sigma * rng.gaussian()).round().clamp(0.0, 255.0) as u8;
            }
            f
        })
        .collect()
}

/// The SIMULATED scene depth without noise [m], row-major: a plane at `z_plane` with the face
/// (the canonical model at the first frame's PnP pose, nearest vertex within 6 px) in it.
fn scene_depth(intr: &Intrinsics, z_plane: f64, face: Option<&[Point3<f64>]>) -> (Vec<f64>, usize) {
    let (w, h) = (intr.width as usize, intr.height as usize);
    let mut z = vec![z_plane; w * h];
    let mut face_px = 0;
    let Some(face) = face else {
        return (z, 0);
    };
    let proj: Vec<(f64, f64, f64)> = face
        .iter()
        .filter_map(|p| intr.project(p).map(|(u, v)| (u, v, p.z)))
        .collect();
    let min = |f: fn(&(f64, f64, f64)) -> f64| proj.iter().map(f).fold(f64::INFINITY, f64::min);
    let max = |f: fn(&(f64, f64, f64)) -> f64| proj.iter().map(f).fold(f64::NEG_INFINITY, f64::max);
    let (u0, u1) = (min(|p| p.0).floor().max(0.0), max(|p| p.0).ceil());
    let (v0, v1) = (min(|p| p.1).floor().max(0.0), max(|p| p.1).ceil());
    for y in (v0 as usize)..(v1 as usize).min(h) {
        for x in (u0 as usize)..(u1 as usize).min(w) {
            let best = proj.iter().fold((f64::INFINITY, 0.0), |b, p| {
                let d = (p.0 - x as f64).powi(2) + (p.1 - y as f64).powi(2);
                if d < b.0 { (d, p.2) } else { b }
            });
            if best.0 <= 36.0 {
                z[y * w + x] = best.1;
                face_px += 1;
            }
        }
    }
    (z, face_px)
}

/// Frame `k`'s SIMULATED depth image: the scene shifted by `shift` [px], D400 noise, 1 mm units.
fn depth_frame(scene: &[f64], intr: &Intrinsics, shift: i64, rng: &mut SplitMix64) -> DepthImage {
    let (w, h) = (intr.width as usize, intr.height as usize);
    let mut data = vec![0u16; w * h];
    for y in 0..h {
        for x in 0..w {
            let sx = (x as i64 - shift).clamp(0, w as i64 - 1) as usize;
            let z = scene[y * w + sx];
            let sigma = z * z * DEPTH_SUBPIXEL / (DEPTH_FOCAL_PX * DEPTH_BASELINE_M);
            let noisy = z + sigma * rng.gaussian();
            data[y * w + x] = (noisy / DEPTH_UNIT_M).round().clamp(0.0, 65535.0) as u16;
        }
    }
    DepthImage {
        width: intr.width,
        height: intr.height,
        data,
        scale_m: DEPTH_UNIT_M,
    }
}

/// One frame's cues and landmark scores.
struct Sample {
    cues: PerceivedCues,
    /// Face score, pose score × the smaller shoulder visibility, mean hand score (None: absent).
    lm: [Option<f64>; 3],
    /// The face landmarks [px].
    face: Option<Vec<Landmark>>,
}

fn run(
    pipeline: &mut Pipeline,
    canonical: &[Point3<f64>],
    frames: &[RgbImage],
    depth: Option<&dyn Fn(usize) -> DepthImage>,
) -> Res<Vec<Sample>> {
    pipeline.reset();
    let mut extractor = CueExtractor::new(
        CueConfig::default(),
        Extrinsics::identity(),
        canonical.to_vec(),
    )?;
    let mut out = Vec::with_capacity(frames.len());
    for (k, image) in frames.iter().enumerate() {
        let t = k as f64 / FPS;
        let intr = Intrinsics::from_hfov(image.width, image.height, HFOV_DEG);
        let d = depth.map(|f| f(k));
        let lm: Landmarks = pipeline.process_at(t, image, d.as_ref())?;
        let cues = extractor.extract(t, &lm, d.as_ref(), &intr);
        let hands = (!lm.hands.is_empty())
            .then(|| lm.hands.iter().map(|h| h.score).sum::<f64>() / lm.hands.len() as f64);
        out.push(Sample {
            lm: [
                lm.face.as_ref().map(|f| f.score),
                lm.pose
                    .as_ref()
                    .map(|p| p.score * p.points[11].visibility.min(p.points[12].visibility)),
                hands,
            ],
            cues,
            face: lm.face.map(|f| f.points),
        });
    }
    Ok(out)
}

/// One cue's series: per frame (after [`SETTLE`]) the values, confidence, landmark score.
#[derive(Default)]
struct Series {
    x: Vec<Option<Vec3>>,
    conf: Vec<f64>,
    lm: Vec<f64>,
    depth_share: f64,
}

/// Standard deviations per axis after a linear detrend, per-axis RMS, from differences, lag-1
/// autocorrelation (mean over axes), trend speed [unit/s], samples.
struct Stats {
    sd: [f64; 3],
    rms: f64,
    diff: f64,
    r1: f64,
    trend: f64,
    n: usize,
}

fn stats(x: &[Option<Vec3>], axes: usize) -> Option<Stats> {
    let pts: Vec<(f64, Vec3)> = x
        .iter()
        .enumerate()
        .filter_map(|(k, v)| v.map(|v| (k as f64, v)))
        .collect();
    let n = pts.len();
    if n < 20 {
        return None;
    }
    let tm = pts.iter().map(|p| p.0).sum::<f64>() / n as f64;
    let stt = pts.iter().map(|p| (p.0 - tm).powi(2)).sum::<f64>();
    let (mut sd, mut r1, mut dsum, mut slope2) = ([f64::NAN; 3], 0.0, 0.0, 0.0);
    for (a, sd_a) in sd.iter_mut().enumerate().take(axes) {
        let ym = pts.iter().map(|p| p.1[a]).sum::<f64>() / n as f64;
        let b = pts.iter().map(|p| (p.0 - tm) * (p.1[a] - ym)).sum::<f64>() / stt;
        slope2 += b * b;
        let mut res: Vec<Option<f64>> = vec![None; x.len()];
        for p in &pts {
            res[p.0 as usize] = Some(p.1[a] - ym - b * (p.0 - tm));
        }
        let var = res.iter().flatten().map(|r| r * r).sum::<f64>() / (n - 2) as f64;
        *sd_a = var.sqrt();
        let pairs: Vec<(f64, f64)> = res
            .windows(2)
            .filter_map(|w| Some((w[0]?, w[1]?)))
            .collect();
        let num: f64 = pairs.iter().map(|(p, q)| p * q).sum();
        let den: f64 = res.iter().flatten().map(|r| r * r).sum::<f64>();
        r1 += num / den * n as f64 / pairs.len().max(1) as f64;
        let dm = pairs.iter().map(|(p, q)| q - p).sum::<f64>() / pairs.len() as f64;
        dsum += pairs.iter().map(|(p, q)| (q - p - dm).powi(2)).sum::<f64>()
            / (pairs.len() - 1) as f64
            / 2.0;
    }
    let k = axes as f64;
    Some(Stats {
        rms: (sd[..axes].iter().map(|s| s * s).sum::<f64>() / k).sqrt(),
        sd,
        diff: (dsum / k).sqrt(),
        r1: r1 / k,
        trend: slope2.sqrt() * FPS,
        n,
    })
}

/// Facing vectors → the two angles [rad] about their mean direction (as `x`, `y`; `z` = 0).
fn angles(f: &[Option<Vec3>]) -> Vec<Option<Vec3>> {
    let mean: Vec3 = f.iter().flatten().map(|v| v.normalize()).sum();
    if mean.norm() < 1e-9 {
        return vec![None; f.len()];
    }
    let m = mean.normalize();
    let helper = if m.x.abs() < 0.9 {
        Vec3::x()
    } else {
        Vec3::y()
    };
    let e1 = m.cross(&helper).normalize();
    let e2 = m.cross(&e1);
    f.iter()
        .map(|v| {
            v.map(|v| {
                let v = v.normalize();
                Vec3::new(
                    v.dot(&e1).atan2(v.dot(&m)),
                    v.dot(&e2).atan2(v.dot(&m)),
                    0.0,
                )
            })
        })
        .collect()
}

/// The §7 filtered hand speed v_h [m/s] of a position series: median and 90th percentile over
/// the frames from 0.5 s after the filter's start (a missing hand re-initialises the filter).
fn filtered_speed(x: &[Option<Vec3>]) -> Option<(f64, f64)> {
    let mut filter = OneEuro3::new(HesitationConfig::default().one_euro);
    let mut prev: Option<[f64; 3]> = None;
    let mut v = Vec::new();
    for (k, p) in x.iter().enumerate() {
        match p {
            Some(p) => {
                let y = filter.filter([p.x, p.y, p.z], 1.0 / FPS);
                if let Some(q) = prev
                    && k >= 15
                {
                    let d = (y[0] - q[0]).hypot(y[1] - q[1]).hypot(y[2] - q[2]);
                    v.push(d * FPS);
                }
                prev = Some(y);
            }
            None => {
                filter.reset();
                prev = None;
            }
        }
    }
    if v.len() < 10 {
        return None;
    }
    v.sort_by(f64::total_cmp);
    Some((v[v.len() / 2], v[v.len() * 9 / 10]))
}

const CUES: [&str; 6] = [
    "head_pos",
    "head_facing",
    "torso_pos",
    "torso_facing",
    "hand_left",
    "hand_right",
];

/// The six cue series of one run.
fn series(samples: &[Sample]) -> [Series; 6] {
    let mut s: [Series; 6] = Default::default();
    let mut depth = [0usize; 6];
    for smp in &samples[SETTLE..] {
        let f = &smp.cues.frame;
        let d = usize::from(smp.cues.quality == assess::vision::cues::CueQuality::Depth3d);
        let vals: [Option<(Vec3, f64, Option<f64>)>; 6] = [
            f.head.map(|h| (h.position, h.confidence, smp.lm[0])),
            f.head.map(|h| (h.facing, h.confidence, smp.lm[0])),
            f.body.map(|b| (b.position, b.confidence, smp.lm[1])),
            f.body.map(|b| (b.facing, b.confidence, smp.lm[1])),
            f.hands[0].map(|h| (h.position, h.confidence, smp.lm[2])),
            f.hands[1].map(|h| (h.position, h.confidence, smp.lm[2])),
        ];
        for (i, v) in vals.into_iter().enumerate() {
            s[i].x.push(v.map(|v| v.0));
            if let Some((_, c, lm)) = v {
                s[i].conf.push(c);
                s[i].lm.extend(lm);
                depth[i] += d;
            }
        }
    }
    for (si, d) in s.iter_mut().zip(depth) {
        si.depth_share = d as f64 / si.conf.len().max(1) as f64;
    }
    s[1].x = angles(&s[1].x);
    s[3].x = angles(&s[3].x);
    s
}

const HEADER: &str = "photo,scale,motion,depth,cue,unit,n,depth_share,conf_mean,conf_min,conf_max,\
                      lm_score_mean,sd_x,sd_y,sd_z,sd_axis_rms,sd_diff,lag1_autocorr,\
                      trend_per_s,vh_median_m_s,vh_p90_m_s";

/// CSV rows of one run (missing cues: a row with n = 0).
fn rows(photo: &str, scale: f64, motion: &str, depth: &str, s: &[Series; 6], out: &mut String) {
    for (i, (name, se)) in CUES.iter().zip(s).enumerate() {
        let facing = i == 1 || i == 3;
        let unit = if facing { "rad" } else { "m" };
        let st = stats(&se.x, if facing { 2 } else { 3 });
        let vh = (i >= 4).then(|| filtered_speed(&se.x)).flatten();
        let g = |v: f64| format!("{v:.5}");
        let (conf, lm) = (&se.conf, &se.lm);
        let cmin = conf.iter().copied().fold(f64::INFINITY, f64::min);
        let cmax = conf.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let _ = write!(
            out,
            "{photo},{scale},{motion},{depth},{name},{unit},{},{:.2},{},{},{},{}",
            st.as_ref().map_or(conf.len(), |s| s.n),
            se.depth_share,
            if conf.is_empty() {
                String::new()
            } else {
                format!("{:.3}", mean(conf))
            },
            if conf.is_empty() {
                String::new()
            } else {
                format!("{cmin:.3}")
            },
            if conf.is_empty() {
                String::new()
            } else {
                format!("{cmax:.3}")
            },
            if lm.is_empty() {
                String::new()
            } else {
                format!("{:.3}", mean(lm))
            },
        );
        match st {
            Some(st) => {
                let z = if facing { String::new() } else { g(st.sd[2]) };
                let _ = write!(
                    out,
                    ",{},{},{z},{},{},{:.3},{}",
                    g(st.sd[0]),
                    g(st.sd[1]),
                    g(st.rms),
                    g(st.diff),
                    st.r1,
                    g(st.trend)
                );
            }
            None => out.push_str(",,,,,,,"),
        }
        match vh {
            Some((m, p)) => {
                let _ = writeln!(out, ",{},{}", g(m), g(p));
            }
            None => out.push_str(",,\n"),
        }
    }
}

/// The operator's own noise model (iid Gaussian, `noise3` / `noisy_direction`) through the
/// same statistics: still head, torso and hands.
fn simulator_rows(out: &mut String) {
    let mut rng = SplitMix64(0x0e7a_70c5_0000_0014);
    let mut noise3 = |s: f64| Vec3::new(rng.gaussian(), rng.gaussian(), rng.gaussian()) * s;
    let n = FRAMES - SETTLE;
    let mut s: [Series; 6] = Default::default();
    let facing = Vec3::new(0.3, 0.0, -1.0).normalize();
    for _ in 0..n {
        let vals = [
            Vec3::new(0.0, 0.0, 1.2) + noise3(0.005),
            (facing + noise3(0.04)).normalize(),
            Vec3::new(0.0, 0.0, 0.95) + noise3(0.005),
            (facing + noise3(0.04)).normalize(),
            Vec3::new(-0.2, 0.3, 0.9) + noise3(0.005),
            Vec3::new(0.2, 0.3, 0.9) + noise3(0.005),
        ];
        let conf = [0.9, 0.9, 0.85, 0.85, 0.8, 0.8];
        for ((se, v), c) in s.iter_mut().zip(vals).zip(conf) {
            se.x.push(Some(v));
            se.conf.push(c);
        }
    }
    s[1].x = angles(&s[1].x);
    s[3].x = angles(&s[3].x);
    rows("simulator", 1.0, "still", "-", &s, out);
}

/// The §7 filtered speed of a still hand whose positions carry AR(1) noise (per axis σ, lag-1
/// autocorrelation ρ), per σ: median and 90th percentile of v_h / σ [1/s] over 30 000 frames.
fn ar1_speed_per_sigma(rho: f64) -> (f64, f64) {
    let mut rng = SplitMix64(0x0a71_0000_0014 ^ (rho * 100.0) as u64);
    let mut e = Vec3::zeros();
    let innov = (1.0 - rho * rho).sqrt();
    let x: Vec<Option<Vec3>> = (0..30_000)
        .map(|_| {
            e = e * rho + Vec3::new(rng.gaussian(), rng.gaussian(), rng.gaussian()) * innov;
            Some(e * 0.001)
        })
        .collect();
    filtered_speed(&x).map_or((f64::NAN, f64::NAN), |(m, p)| (m / 0.001, p / 0.001))
}

fn main() -> Res<()> {
    let out_path = std::env::args().nth(1).map_or_else(
        || PathBuf::from("docs/calibration/cue_noise.csv"),
        PathBuf::from,
    );
    let t0 = Instant::now();
    models::init_runtime(None)?;
    let models_dir = models::model_dir();
    let mut pipeline = Pipeline::load(
        &models_dir,
        PipelineConfig {
            mode: Mode::Tracking,
            ..PipelineConfig::default()
        },
    )?;
    let canonical = load_canonical_face(&models_dir.join("canonical_face_model.csv"))?;
    let images = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/images");
    let mut csv = String::from(HEADER);
    csv.push('\n');
    let mut notes = String::new();
    for (p, &(file, scale)) in PHOTOS.iter().enumerate() {
        let src = RgbImage::read(&images.join(file))?;
        for motion in [Motion::Still, Motion::Pan] {
            let seed = 0x14c0_e000_0000_0000 ^ ((p as u64) << 40) ^ ((motion as u64) << 36);
            let frames = frames(&src, scale, motion, seed);
            let intr = Intrinsics::from_hfov(moving::W, moving::H, HFOV_DEG);
            let plain = run(&mut pipeline, &canonical, &frames, None)?;
            // The SIMULATED scene depth: the first used frame's PnP face pose and distance.
            let face = plain.iter().enumerate().skip(SETTLE).find_map(|(k, s)| {
                let (r, t) = pnp(&canonical, s.face.as_ref()?, &intr)?;
                let pts: Vec<Point3<f64>> = canonical
                    .iter()
                    .map(|c| Point3::from(r * c.coords + t))
                    .collect();
                Some((k, t.z, pts))
            });
            let z_plane = face.as_ref().map_or(DEFAULT_Z_M, |f| f.1);
            let (scene, face_px) = scene_depth(&intr, z_plane, face.as_ref().map(|f| &f.2[..]));
            let k_face = face.as_ref().map_or(0, |f| f.0);
            let depth_of = |k: usize| {
                let shift = (motion.pan(k) - motion.pan(k_face)).round() as i64;
                let mut rng = SplitMix64(seed ^ 0xd ^ ((k as u64) << 8));
                depth_frame(&scene, &intr, shift, &mut rng)
            };
            let with_depth = run(&mut pipeline, &canonical, &frames, Some(&depth_of))?;
            let _ = writeln!(
                notes,
                "{file} ×{scale} {}: depth plane {z_plane:.3} m (σ_z {:.4} m), face rendered on {face_px} px",
                motion.name(),
                z_plane * z_plane * DEPTH_SUBPIXEL / (DEPTH_FOCAL_PX * DEPTH_BASELINE_M)
            );
            rows(file, scale, motion.name(), "no", &series(&plain), &mut csv);
            rows(
                file,
                scale,
                motion.name(),
                "yes",
                &series(&with_depth),
                &mut csv,
            );
        }
    }
    simulator_rows(&mut csv);
    if let Some(dir) = out_path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)?;
    }
    std::fs::write(&out_path, &csv)?;
    print_table(&csv);
    println!("\nfiltered speed v_h of a still hand with AR(1) noise, per unit σ (per axis):");
    for rho in [0.0, 0.3, 0.5, 0.7, 0.85] {
        let (m, p) = ar1_speed_per_sigma(rho);
        println!("  lag-1 {rho:.2}: median v_h = {m:.2} σ/s, p90 = {p:.2} σ/s");
    }
    eprint!("{notes}");
    eprintln!(
        "cue_noise: wrote {} in {:.1} s",
        out_path.display(),
        t0.elapsed().as_secs_f64()
    );
    Ok(())
}

/// The CSV as an aligned table on stdout (the main columns).
fn print_table(csv: &str) {
    let keep = [0, 1, 2, 3, 4, 6, 8, 11, 12, 13, 14, 15, 16, 17, 19];
    for line in csv.lines() {
        let cells: Vec<&str> = line.split(',').collect();
        let row: Vec<String> = keep
            .iter()
            .enumerate()
            .map(|(j, &i)| {
                let c = cells.get(i).copied().unwrap_or("");
                if j == 0 {
                    format!("{c:<20}")
                } else if j <= 4 {
                    format!("{c:<12}")
                } else {
                    format!("{c:>9}")
                }
            })
            .collect();
        println!("{}", row.join(" "));
    }
}
