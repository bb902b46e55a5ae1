//! `Assessor::update` allocates nothing after construction (counting global allocator).
//!
//! The counter (`hrc_adapt_tests::alloc_count`) is per thread, so allocations of the test
//! harness's other threads don't count.

use assess::{
    AssessConfig, Assessor, BaselineMode, BodyCue, CueFrame, HandCue, HeadCue, RobotContext, Vec3,
    Workspace,
};
use hrc_adapt_tests::alloc_count::{CountingAllocator, allocations_in};

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

/// A small deterministic generator (no allocation).
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

fn frame(k: u64, rng: &mut Lcg) -> CueFrame {
    // A busy operator: gaze wandering over all areas, torso turning, both hands moving or
    // resting, dropouts, NaN cues, irregular intervals and gaps, collaboration periods.
    let t = k as f64 / 30.0 + if k.is_multiple_of(97) { 0.5 } else { 0.0 } + (k / 97) as f64 * 0.5;
    let phase = k as f64 * 0.07;
    let gaze = Vec3::new(phase.cos(), phase.sin(), -0.3 + 0.2 * (phase * 3.0).sin());
    let torso = Vec3::new((phase * 0.5).cos(), (phase * 0.5).sin(), 0.0);
    let still = (k / 40) % 3 == 1;
    let (c_left, c_right, c_head) = (rng.next(), rng.next(), rng.next());
    let hand = |off: f64, confidence: f64| HandCue {
        position: if still {
            Vec3::new(0.5 + off, 0.0, 0.8)
        } else {
            Vec3::new(0.5 + 0.2 * phase.sin() + off, 0.2 * phase.cos(), 0.8)
        },
        confidence,
    };
    CueFrame {
        t,
        head: (!k.is_multiple_of(13)).then_some(HeadCue {
            position: Vec3::new(0.0, 0.0, 1.5),
            facing: if k.is_multiple_of(31) {
                Vec3::new(f64::NAN, 0.0, 0.0)
            } else {
                gaze
            },
            confidence: 0.2 + 0.8 * c_head,
        }),
        body: (!k.is_multiple_of(7)).then_some(BodyCue {
            position: Vec3::new(0.0, 0.0, 1.3),
            facing: torso,
            confidence: 0.9,
        }),
        hands: [
            (!k.is_multiple_of(50)).then(|| hand(0.0, 0.5 + 0.5 * c_left)),
            (!k.is_multiple_of(70)).then(|| hand(0.1, 0.5 + 0.5 * c_right)),
        ],
        robot: RobotContext {
            collaborating: (k / 90) % 2 == 1,
            incomplete: (k / 60) % 4 != 3,
        },
    }
}

fn workspace() -> Workspace {
    Workspace::from_toml_file(hrc_adapt_tests::config_dir().join("example-workspace.toml")).unwrap()
}

fn allocations_during(cfg: AssessConfig, frames: u64) -> u64 {
    let mut a = Assessor::new(workspace(), cfg).unwrap();
    let mut rng = Lcg(42);
    let mut valid = 0u64;
    let mut hes = 0u64;
    let mut dominant = 0u64;
    let ((), allocations) = allocations_in(|| {
        for k in 0..frames {
            let out = a.update(&frame(k, &mut rng));
            valid += out.valid as u64;
            hes += out.hesitating as u64;
            dominant += out.dominant.indicator.is_some() as u64;
        }
    });
    // The run must have exercised the interesting paths, or the test proves little.
    assert!(valid > frames / 2, "valid frames: {valid}");
    assert!(hes > 0, "no hesitation frames");
    assert!(dominant > 0, "no dominant indicator");
    allocations
}

#[test]
fn update_allocates_nothing_with_default_config() {
    // 20 000 frames ≈ 11 min of 30 fps input: the 30 s window and the 10 s median both wrap
    // many times, and the 60 s calibration ends.
    assert_eq!(allocations_during(AssessConfig::default(), 20_000), 0);
}

#[test]
fn update_allocates_nothing_when_the_window_ring_overflows() {
    // A window sized for 5 Hz input fed at 30 Hz: the ring overflows on every frame.
    let mut cfg = AssessConfig::default();
    cfg.window.max_rate_hz = 5.0;
    cfg.dominant.baseline_mode = BaselineMode::Fixed;
    assert_eq!(allocations_during(cfg, 5_000), 0);
}

#[test]
fn the_counter_counts() {
    // Guard against a counter that can't fail: an allocation inside the counted region counts.
    let (v, n) = allocations_in(|| std::hint::black_box(Vec::<u64>::with_capacity(8)));
    drop(v);
    assert_eq!(n, 1);
}
