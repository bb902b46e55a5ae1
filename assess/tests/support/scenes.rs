//! Three more moving-video scenes of issue 13, point 2, all SIMULATED motion of real bundled
//! photos, made the same way by the test `vision_scenes.rs` and by the example `moving_video`
//! (`make <dir> --scene <name>`, which writes them for mediapipe's reference):
//!
//! - [`Scene::EnterLeave`]: `pose_sitting.jpg` scaled by 0.6 (576 × 384) into the 640 × 480
//!   frame slides in from the left over 28 frames (≈ 0.9 s), stays 28 frames, slides out to the
//!   right over 28 frames, with 8 empty (black) frames before and after: 100 frames.
//! - [`Scene::HandExit`]: `hand_thumb_up.jpg` (640 × 521) scaled by 0.85 is panned right by
//!   `320 (1 − cos(2πk/90))` px: the hand leaves across the right edge, is out of the frame for
//!   a few frames around frame 45 and comes back: 90 frames.
//! - [`Scene::LowLight`]: the pan/zoom/roll frames of `moving.rs` darkened, each value
//!   `255 · 0.25 · (v/255)²` plus sensor noise (σ = 2 levels, approximately Gaussian: the sum
//!   of 4 uniforms of the fixed-seed PRNG [`SplitMix64`], seeded per frame; arithmetic only, no
//!   libm) and rounded to u8: 90 frames.
//!
//! The warp is `moving.rs`'s ([`crate::moving::warp`]), so every pixel is the same on every
//! machine and each frame's FNV-1a checksum is recorded in the fixture.

use assess::vision::RgbImage;

use crate::moving;

/// One of the SIMULATED scenes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Scene {
    /// A seated person slides in from the left, stays, slides out to the right.
    EnterLeave,
    /// A hand is panned out of the frame across the right edge and back.
    HandExit,
    /// The pan/zoom/roll motion of `moving.rs`, darkened, with sensor noise.
    LowLight,
}

/// The low-light gain [-] (the gamma is 2) and noise standard deviation [levels].
const LOW_LIGHT: (f64, f64) = (0.25, 2.0);

impl Scene {
    /// Every scene, in the order of the fixtures.
    pub(crate) const ALL: [Scene; 3] = [Scene::EnterLeave, Scene::HandExit, Scene::LowLight];

    /// The name on the command line (`moving_video make --scene <name>`).
    pub(crate) fn name(self) -> &'static str {
        match self {
            Scene::EnterLeave => "enter-leave",
            Scene::HandExit => "hand-exit",
            Scene::LowLight => "low-light",
        }
    }

    /// The scene called `name`.
    pub(crate) fn parse(name: &str) -> Option<Scene> {
        Scene::ALL.into_iter().find(|s| s.name() == name)
    }

    /// The bundled photo the scene moves, under `data/images/`.
    pub(crate) fn photo(self) -> &'static str {
        match self {
            Scene::EnterLeave | Scene::LowLight => "pose_sitting.jpg",
            Scene::HandExit => "hand_thumb_up.jpg",
        }
    }

    /// The number of frames of the scene (of its fixture).
    pub(crate) fn frames(self) -> usize {
        match self {
            Scene::EnterLeave => 100,
            Scene::HandExit | Scene::LowLight => 90,
        }
    }

    /// The fixture's file name, under `tests/fixtures/vision/`.
    pub(crate) fn fixture(self) -> String {
        format!("mediapipe_scene_{}.json", self.name().replace('-', "_"))
    }

    /// What the frames show, for `frames.json` and the fixture.
    pub(crate) fn description(self) -> &'static str {
        match self {
            Scene::EnterLeave => {
                "SIMULATED: the real photo data/images/pose_sitting.jpg (scaled 0.6) slides into \
                 the frame from the left, stays, slides out to the right; 8 empty frames before \
                 and after"
            }
            Scene::HandExit => {
                "SIMULATED: the real photo data/images/hand_thumb_up.jpg (scaled 0.85) panned out \
                 of the frame across the right edge and back"
            }
            Scene::LowLight => {
                "SIMULATED: the pan/zoom/roll motion of the real photo \
                 data/images/pose_sitting.jpg, darkened (gain 0.25, gamma 2) with sensor noise \
                 (sigma 2 levels, sum of 4 uniforms of a fixed-seed SplitMix64)"
            }
        }
    }

    /// The motion of frame `k`: scale of the photo [-], pan right and down [px], roll [deg].
    pub(crate) fn motion(self, k: usize) -> (f64, [f64; 2], f64) {
        match self {
            Scene::EnterLeave => {
                // Centre offsets: −640 (out on the left) → 0 → +640 (out on the right); the
                // 576 px wide photo is wholly outside at |offset| ≥ 608.
                let x = match k {
                    0..8 => -640.0,
                    8..36 => -640.0 + 640.0 * (k - 8) as f64 / 28.0,
                    36..64 => 0.0,
                    64..92 => 640.0 * (k - 63) as f64 / 28.0,
                    _ => 640.0,
                };
                (0.6, [x, 0.0], 0.0)
            }
            Scene::HandExit => {
                let c = (std::f64::consts::TAU * k as f64 / 90.0).cos();
                (0.85, [320.0 * (1.0 - c), 0.0], 0.0)
            }
            Scene::LowLight => {
                let (pan, zoom, roll) = moving::motion(k);
                (0.75 * zoom, [pan, 0.0], roll)
            }
        }
    }

    /// Frame `k` made from `src` (the scene's [`Scene::photo`]).
    pub(crate) fn frame(self, src: &RgbImage, k: usize) -> RgbImage {
        self.frame_shifted(src, k, 0.0)
    }

    /// Frame `k` with the photo panned `dx` [px] further right, the same sensor noise on the
    /// same pixels (the tests' measure of the models' own sensitivity).
    pub(crate) fn frame_shifted(self, src: &RgbImage, k: usize, dx: f64) -> RgbImage {
        let (scale, pan, roll) = self.motion(k);
        let mut out = moving::warp(src, scale, [pan[0] + dx, pan[1]], roll);
        if self == Scene::LowLight {
            let (gain, sigma) = LOW_LIGHT;
            let mut rng = SplitMix64(0x5eed_10e1_1647_0000 ^ k as u64);
            for v in &mut out.data {
                let u = f64::from(*v) / 255.0;
                let dark = 255.0 * gain * u * u;
                *v = (dark + sigma * rng.gaussian()).round().clamp(0.0, 255.0) as u8;
            }
        }
        out
    }
}

/// SplitMix64 (Steele, Lea and Flood 2014): a small fixed-seed PRNG, the same on every machine.
pub(crate) struct SplitMix64(pub(crate) u64);

impl SplitMix64 {
    /// The next 64 random bits.
    pub(crate) fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Approximately a standard normal deviate: the sum of four uniforms (the four 16-bit
    /// lanes of one draw) centred and scaled to variance 1 (Irwin–Hall), arithmetic only so that
    /// it is the same on every machine.
    pub(crate) fn gaussian(&mut self) -> f64 {
        let z = self.next_u64();
        let sum: f64 = (0..4)
            .map(|i| (((z >> (16 * i)) & 0xffff) as f64 + 0.5) / 65536.0)
            .sum();
        (sum - 2.0) * 3f64.sqrt()
    }
}
