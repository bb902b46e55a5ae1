//! The moving video of issue 13 and the landmark pipeline on it, for the side-by-side benchmark
//! against mediapipe's Python video mode (`scripts/bench/side-by-side`, BENCHMARKS.md "Moving
//! video, side by side") and for the reference of the test `vision_moving.rs`
//! (`scripts/models/reference`).
//!
//! - `moving_video make <dir> [--frames N]` writes the frames of `tests/support/moving.rs`
//!   (SIMULATED motion of `data/images/pose_sitting.jpg`, 640 × 480) as lossless PNGs
//!   `<dir>/000000.png`, … and `<dir>/frames.json` (each frame's motion and checksum).
//! - `moving_video make <dir> --scene enter-leave|hand-exit|low-light [--frames N]` writes one
//!   of the SIMULATED scenes of `tests/support/scenes.rs` instead (a person entering and
//!   leaving, a hand leaving the frame, low light; by default the scene's own frame count), for
//!   the references of the test `vision_scenes.rs`.
//! - `moving_video run <dir> <out.json>` decodes every PNG of `<dir>` first (timed on its own),
//!   then runs [`Pipeline`] in tracking mode with the default (full) models and extracts the
//!   cues (no depth: the PnP head pose) as the trial does, frame by frame, at 30 fps camera
//!   time. It writes `<out.json>`:
//!   - `frames`: per frame, the pose (33), face (468) and hand (21 each) landmarks [px];
//!   - `decode_s` (all frames), `pipeline_s`, `cues_s` (summed over the frames): wall time [s];
//!   - `stages_s`: the pipeline's stage times ([`StageTimes`]) summed over the frames [s];
//!   - `runs`: how often each model ran ([`RunCounts`]), so re-detections are visible;
//!   - `loop_wall_s`, `loop_cpu_s`: wall and CPU time (user + system, all threads, from
//!     `/proc/self/stat`) of the frame loop, model loading and decoding excluded [s].
//!
//! Run with `cargo run --release -p assess --features vision --example moving_video -- …`
//! (after `scripts/setup`; `source scripts/deps/env.sh` for ONNX Runtime).

use std::path::{Path, PathBuf};
use std::time::Instant;

use assess::vision::cues::{CueConfig, CueExtractor, load_canonical_face};
use assess::vision::pipeline::{Mode, Pipeline, PipelineConfig, RunCounts, StageTimes};
use assess::vision::{Extrinsics, Intrinsics, Landmark, RgbImage, models};

#[path = "../tests/support/moving.rs"]
mod moving;
#[path = "../tests/support/scenes.rs"]
mod scenes;

type Res<T> = Result<T, Box<dyn std::error::Error>>;

/// Process CPU time (user + system, all threads) [s], from `/proc/self/stat` (clock ticks of
/// 1/100 s, Linux's USER_HZ).
fn cpu_s() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    // After the command name (in parentheses, may hold spaces) utime and stime are the 12th
    // and 13th fields (fields 14 and 15 of the line).
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let f: Vec<f64> = rest
        .split_whitespace()
        .map(|s| s.parse().unwrap_or(0.0))
        .collect();
    match (f.get(11), f.get(12)) {
        (Some(u), Some(s)) => (u + s) / 100.0,
        _ => f64::NAN,
    }
}

fn points(p: &[Landmark]) -> Vec<[f64; 2]> {
    p.iter().map(|l| [l.x, l.y]).collect()
}

fn add(sum: &mut [f64; 7], t: &StageTimes) {
    let us = [
        t.pose_detection_us,
        t.pose_landmarks_us,
        t.face_detection_us,
        t.face_landmarks_us,
        t.palm_detection_us,
        t.hand_landmarks_us,
        t.total_us,
    ];
    for (s, u) in sum.iter_mut().zip(us) {
        *s += u as f64 * 1e-6;
    }
}

fn runs_json(r: &RunCounts) -> serde_json::Value {
    serde_json::json!({
        "frames": r.frames,
        "pose_detector": r.pose_detector,
        "face_detector": r.face_detector,
        "palm_detector": r.palm_detector,
        "pose_landmarks": r.pose_landmarks,
        "face_landmarks": r.face_landmarks,
        "hand_landmarks": r.hand_landmarks,
    })
}

/// Writes `frames` frames of `scene` (`None`: the pan/zoom/roll video of `moving.rs`).
fn make(dir: &Path, frames: usize, scene: Option<scenes::Scene>) -> Res<()> {
    let name = scene.map_or("pose_sitting.jpg", scenes::Scene::photo);
    let photo = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../data/images")
        .join(name);
    let src = RgbImage::read(&photo)?;
    std::fs::create_dir_all(dir)?;
    let mut list = Vec::with_capacity(frames);
    for k in 0..frames {
        let (f, motion) = match scene {
            None => {
                let (pan, zoom, roll) = moving::motion(k);
                let m = serde_json::json!({"pan_px": pan, "zoom": zoom, "roll_deg": roll});
                (moving::frame(&src, k), m)
            }
            Some(s) => {
                let (scale, pan, roll) = s.motion(k);
                let m = serde_json::json!({"scale": scale, "pan_px": pan, "roll_deg": roll});
                (s.frame(&src, k), m)
            }
        };
        assess::vision::calib::write_png(&f, dir.join(format!("{k:06}.png")))?;
        let mut entry = serde_json::json!({
            "frame": k,
            "fnv1a": format!("{:016x}", moving::fnv1a(&f.data)),
        });
        entry
            .as_object_mut()
            .unwrap()
            .extend(motion.as_object().unwrap().clone());
        list.push(entry);
    }
    let fixture = scene.map_or("mediapipe_moving.json".to_owned(), scenes::Scene::fixture);
    let (made_by, simulated) = match scene {
        None => (
            "assess/examples/moving_video.rs make (tests/support/moving.rs)".to_owned(),
            "SIMULATED motion (pan, zoom, roll) of the real photo data/images/pose_sitting.jpg",
        ),
        Some(s) => (
            format!(
                "assess/examples/moving_video.rs make --scene {} (tests/support/scenes.rs)",
                s.name()
            ),
            s.description(),
        ),
    };
    let doc = serde_json::json!({
        "made_by": made_by,
        "simulated": simulated,
        "fixture": format!("assess/tests/fixtures/vision/{fixture}"),
        "width": moving::W,
        "height": moving::H,
        "fps": moving::FPS,
        "frames": list,
    });
    std::fs::write(dir.join("frames.json"), serde_json::to_string_pretty(&doc)?)?;
    eprintln!("moving_video: {frames} frames in {}", dir.display());
    Ok(())
}

fn run(dir: &Path, out: &Path) -> Res<()> {
    let mut pngs: Vec<PathBuf> = std::fs::read_dir(dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "png"))
        .collect();
    pngs.sort();
    if pngs.is_empty() {
        return Err(format!("no .png frames in {}", dir.display()).into());
    }
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
    let mut extractor = CueExtractor::new(CueConfig::default(), Extrinsics::identity(), canonical)?;

    // Decode every frame first, as the mediapipe side does, so that the loop times the
    // pipeline alone; decoding is reported on its own.
    let t = Instant::now();
    let decoded = pngs
        .iter()
        .map(|p| RgbImage::read(p))
        .collect::<Result<Vec<_>, _>>()?;
    let decode_s = t.elapsed().as_secs_f64();
    let (mut pipeline_s, mut cues_s) = (0.0, 0.0);
    let mut stages = [0.0; 7];
    let mut frames = Vec::with_capacity(decoded.len());
    let (wall0, cpu0) = (Instant::now(), cpu_s());
    for (k, image) in decoded.iter().enumerate() {
        let t_cam = k as f64 / moving::FPS;
        let intrinsics = Intrinsics::from_hfov(image.width, image.height, 69.0);
        let t = Instant::now();
        let lm = pipeline.process_at(t_cam, image, None)?;
        pipeline_s += t.elapsed().as_secs_f64();
        add(&mut stages, &pipeline.stage_times());
        let t = Instant::now();
        std::hint::black_box(extractor.extract(t_cam, &lm, None, &intrinsics));
        cues_s += t.elapsed().as_secs_f64();
        frames.push(serde_json::json!({
            "frame": k,
            "pose": lm.pose.as_ref().map(|p| points(&p.points)),
            "face": lm.face.as_ref().map(|f| points(&f.points)),
            "hands": lm.hands.iter().map(|h| points(&h.points)).collect::<Vec<_>>(),
        }));
    }
    let (loop_wall_s, loop_cpu_s) = (wall0.elapsed().as_secs_f64(), cpu_s() - cpu0);
    let n = frames.len();
    let doc = serde_json::json!({
        "tool": "assess/examples/moving_video.rs run (hrc-adapt)",
        "input": dir,
        "frames": frames,
        "decode_s": decode_s,
        "pipeline_s": pipeline_s,
        "cues_s": cues_s,
        "stages_s": {
            "pose_detection": stages[0],
            "pose_landmarks": stages[1],
            "face_detection": stages[2],
            "face_landmarks": stages[3],
            "palm_detection": stages[4],
            "hand_landmarks": stages[5],
            "total": stages[6],
        },
        "runs": runs_json(&pipeline.run_counts()),
        "loop_wall_s": loop_wall_s,
        "loop_cpu_s": loop_cpu_s,
    });
    std::fs::write(out, serde_json::to_string(&doc)?)?;
    eprintln!(
        "moving_video: {n} frames, {:.1} fps wall ({:.1} ms/frame pipeline; decoding before: {:.1} ms/frame), {:.2} s CPU",
        n as f64 / loop_wall_s,
        1e3 * pipeline_s / n as f64,
        1e3 * decode_s / n as f64,
        loop_cpu_s
    );
    Ok(())
}

fn main() -> Res<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: moving_video make <dir> [--scene enter-leave|hand-exit|low-light] \
                 [--frames N] | moving_video run <dir> <out.json>";
    let frames = |n: &str| match n.parse::<usize>() {
        Ok(n) if n > 0 => Ok(n),
        _ => Err(format!(
            "--frames must be a positive whole number (got {n})"
        )),
    };
    let scene = |name: &str| {
        scenes::Scene::parse(name).ok_or_else(|| format!("unknown --scene {name}\n{usage}"))
    };
    match args
        .iter()
        .map(String::as_str)
        .collect::<Vec<_>>()
        .as_slice()
    {
        ["make", dir] => make(Path::new(dir), 300, None),
        ["make", dir, "--frames", n] => make(Path::new(dir), frames(n)?, None),
        ["make", dir, "--scene", s] => {
            let s = scene(s)?;
            make(Path::new(dir), s.frames(), Some(s))
        }
        ["make", dir, "--scene", s, "--frames", n] | ["make", dir, "--frames", n, "--scene", s] => {
            make(Path::new(dir), frames(n)?, Some(scene(s)?))
        }
        ["run", dir, out] => run(Path::new(dir), Path::new(out)),
        _ => Err(usage.into()),
    }
}
