//! Benchmark of the camera front-end at 640 × 480, for BENCHMARKS.md ("Perception").
//!
//! Input: the bundled photo `data/images/pose_sitting.jpg` (one seated person, face and both
//! hands visible), letterboxed to 640 × 480 (bilinear, black bars), fed again and again: in
//! tracking mode this is the steady state of a still operator (ROIs tracked, the detectors do
//! not rerun); in static mode every detector runs on every frame.
//!
//! Two measurements per configuration:
//! - criterion's estimate of the time per whole frame (`Pipeline::process`);
//! - a per-frame pass of [`FRAMES`] frames timed one by one, reporting the median, p99 and worst
//!   of every stage (`Pipeline::stage_times`) and of the whole frame, and fps = 1 / median.
//!
//! Cue extraction (landmarks → cues, no depth: the PnP head pose) is measured on its own.
//! Needs the models (`models/`) and ONNX Runtime (`scripts/setup`); run with
//! `cargo bench -p assess --features vision --bench vision`.

use std::hint::black_box;
use std::path::Path;
use std::time::Instant;

use assess::vision::cues::{CueConfig, CueExtractor, load_canonical_face};
use assess::vision::pipeline::{Mode, Pipeline, PipelineConfig, StageTimes, Variant};
use assess::vision::{Extrinsics, Intrinsics, RgbImage, models};
use criterion::Criterion;

/// Frames timed one by one per configuration.
const FRAMES: usize = 200;
/// Frames run before timing (tracking settles, caches warm).
const WARM_UP: usize = 10;

/// The photo, letterboxed into `w` × `h` [px] (bilinear, centred, black bars).
fn letterbox(src: &RgbImage, w: u32, h: u32) -> RgbImage {
    let scale = (f64::from(w) / f64::from(src.width)).min(f64::from(h) / f64::from(src.height));
    let (sw, sh) = (
        (f64::from(src.width) * scale).round() as u32,
        (f64::from(src.height) * scale).round() as u32,
    );
    let (ox, oy) = ((w - sw) / 2, (h - sh) / 2);
    let mut out = RgbImage::black(w, h);
    let px = |x: u32, y: u32, c: usize| {
        f64::from(src.data[(y as usize * src.width as usize + x as usize) * 3 + c])
    };
    for y in 0..sh {
        let fy = ((f64::from(y) + 0.5) / scale - 0.5).clamp(0.0, f64::from(src.height - 1));
        let (y0, ty) = (fy.floor() as u32, fy.fract());
        let y1 = (y0 + 1).min(src.height - 1);
        for x in 0..sw {
            let fx = ((f64::from(x) + 0.5) / scale - 0.5).clamp(0.0, f64::from(src.width - 1));
            let (x0, tx) = (fx.floor() as u32, fx.fract());
            let x1 = (x0 + 1).min(src.width - 1);
            for c in 0..3 {
                let top = px(x0, y0, c) * (1.0 - tx) + px(x1, y0, c) * tx;
                let bottom = px(x0, y1, c) * (1.0 - tx) + px(x1, y1, c) * tx;
                let v = top * (1.0 - ty) + bottom * ty;
                out.data[(((y + oy) * w + x + ox) * 3) as usize + c] = v.round() as u8;
            }
        }
    }
    out
}

fn percentile(sorted: &[u64], p: f64) -> u64 {
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

/// "median / p99 / worst" of a column of µs values; "-" for a stage that never ran.
fn stats(mut v: Vec<u64>) -> String {
    v.retain(|&x| x > 0);
    if v.is_empty() {
        return "-".into();
    }
    v.sort_unstable();
    format!(
        "{:.1} / {:.1} / {:.1} ms ({} runs)",
        percentile(&v, 0.5) as f64 / 1e3,
        percentile(&v, 0.99) as f64 / 1e3,
        v[v.len() - 1] as f64 / 1e3,
        v.len()
    )
}

/// The configurations measured: name and settings.
fn configurations() -> Vec<(&'static str, PipelineConfig)> {
    let tracking = |variant, hand_every, face_every| PipelineConfig {
        variant,
        mode: Mode::Tracking,
        hand_every,
        face_every,
        ..PipelineConfig::default()
    };
    vec![
        ("tracking full", tracking(Variant::Full, 1, 1)),
        ("tracking lite", tracking(Variant::Lite, 1, 1)),
        ("tracking full hand_every=2", tracking(Variant::Full, 2, 1)),
        ("tracking lite hand_every=2", tracking(Variant::Lite, 2, 1)),
        (
            "tracking lite hand_every=2 face_every=2",
            tracking(Variant::Lite, 2, 2),
        ),
        (
            "static full",
            PipelineConfig {
                mode: Mode::Static,
                ..PipelineConfig::default()
            },
        ),
    ]
}

/// Times `FRAMES` frames one by one and prints every stage's median / p99 / worst.
fn per_frame_pass(name: &str, pipeline: &mut Pipeline, image: &RgbImage) {
    for _ in 0..WARM_UP {
        black_box(pipeline.process(image, None).expect("process"));
    }
    let mut times: Vec<StageTimes> = Vec::with_capacity(FRAMES);
    let mut wall: Vec<u64> = Vec::with_capacity(FRAMES);
    for _ in 0..FRAMES {
        let t0 = Instant::now();
        black_box(pipeline.process(image, None).expect("process"));
        wall.push(t0.elapsed().as_micros() as u64);
        times.push(pipeline.stage_times());
    }
    let col = |f: fn(&StageTimes) -> u64| times.iter().map(f).collect::<Vec<u64>>();
    let mut sorted = wall.clone();
    sorted.sort_unstable();
    let median = percentile(&sorted, 0.5) as f64 / 1e6;
    println!("vision/{name}: {FRAMES} frames at 640x480, median / p99 / worst:");
    println!("  pose detection   {}", stats(col(|t| t.pose_detection_us)));
    println!("  pose landmarks   {}", stats(col(|t| t.pose_landmarks_us)));
    println!("  face detection   {}", stats(col(|t| t.face_detection_us)));
    println!("  face landmarks   {}", stats(col(|t| t.face_landmarks_us)));
    println!("  palm detection   {}", stats(col(|t| t.palm_detection_us)));
    println!("  hand landmarks   {}", stats(col(|t| t.hand_landmarks_us)));
    println!("  whole frame      {}", stats(wall));
    println!("  fps = 1 / median = {:.1}", 1.0 / median);
}

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let photo = RgbImage::read(&root.join("data/images/pose_sitting.jpg")).expect("bundled photo");
    let image = letterbox(&photo, 640, 480);
    let dir = models::model_dir();
    let runtime = models::init_runtime(None).expect("ONNX Runtime (run scripts/setup)");
    println!("ONNX Runtime: {}", runtime.display());

    let mut c = Criterion::default()
        .sample_size(20)
        .measurement_time(std::time::Duration::from_secs(8))
        .configure_from_args();
    for (name, config) in configurations() {
        let mut pipeline = Pipeline::load(&dir, config).expect("models (models/)");
        for _ in 0..WARM_UP {
            black_box(pipeline.process(&image, None).expect("process"));
        }
        c.bench_function(&format!("vision/{name} (whole frame)"), |b| {
            b.iter(|| black_box(pipeline.process(black_box(&image), None).expect("process")))
        });
        per_frame_pass(name, &mut pipeline, &image);
    }

    // Cue extraction alone (no depth: PnP head pose), on the tracked landmarks.
    let mut pipeline = Pipeline::load(&dir, PipelineConfig::default()).expect("models (models/)");
    let landmarks = pipeline.process(&image, None).expect("process");
    let canonical =
        load_canonical_face(&dir.join("canonical_face_model.csv")).expect("canonical face");
    let mut extractor = CueExtractor::new(CueConfig::default(), Extrinsics::identity(), canonical)
        .expect("extractor");
    let intrinsics = Intrinsics::from_hfov(640, 480, 69.0);
    let mut t = 0.0;
    c.bench_function("vision/cue extraction (2d, no depth)", |b| {
        b.iter(|| {
            t += 1.0 / 30.0;
            black_box(extractor.extract(t, black_box(&landmarks), None, &intrinsics))
        })
    });
    let mut us: Vec<u64> = (0..2_000)
        .map(|_| {
            t += 1.0 / 30.0;
            let t0 = Instant::now();
            black_box(extractor.extract(t, &landmarks, None, &intrinsics));
            t0.elapsed().as_micros() as u64
        })
        .collect();
    us.sort_unstable();
    println!(
        "vision/cue extraction: 2000 calls, median {} µs, p99 {} µs, worst {} µs",
        percentile(&us, 0.5),
        percentile(&us, 0.99),
        us[us.len() - 1]
    );
    c.final_summary();
}
