//! The moving-video frames of issue 13 (SIMULATED motion of a real photo), made the same way by
//! the test `vision_moving.rs` and by the example `moving_video` (which writes them for
//! mediapipe's reference and for the side-by-side benchmark): `data/images/pose_sitting.jpg`
//! (960 × 640) scaled by 0.75 into a 640 × 480 frame, panned ±60 px (period 150 frames),
//! zoomed 0.85–1.15 (period 200) and rolled ±20° (period 120) about the frame centre.
//!
//! The warp is plain Rust (bilinear, black outside the photo, f64 then rounded), so the pixels
//! are the same on every machine: the fixture records a checksum of each frame
//! ([`fnv1a`]) and the test checks it before comparing landmarks.

use assess::vision::RgbImage;

/// Frame width [px].
pub(crate) const W: u32 = 640;
/// Frame height [px].
pub(crate) const H: u32 = 480;
/// Frame rate [1/s].
pub(crate) const FPS: f64 = 30.0;

/// The motion of frame `k`: pan [px] (positive: right), zoom [-] and roll [deg] (positive:
/// counter-clockwise on screen).
pub(crate) fn motion(k: usize) -> (f64, f64, f64) {
    let k = k as f64;
    let tau = std::f64::consts::TAU;
    (
        60.0 * (tau * k / 150.0).sin(),
        1.0 + 0.15 * (tau * k / 200.0).sin(),
        20.0 * (tau * k / 120.0).sin(),
    )
}

/// Frame `k` made from `src`.
pub(crate) fn frame(src: &RgbImage, k: usize) -> RgbImage {
    frame_shifted(src, k, 0.0)
}

/// Frame `k` made from `src` with the photo panned `dx` [px] further right (the tests' measure
/// of the models' own sensitivity, `compare::SHIFT_PX`).
pub(crate) fn frame_shifted(src: &RgbImage, k: usize, dx: f64) -> RgbImage {
    let (pan, zoom, roll) = motion(k);
    warp(src, 0.75 * zoom, [pan + dx, 0.0], roll)
}

/// `src` scaled by `scale` about its centre, rolled by `roll` [deg] (counter-clockwise on
/// screen) and placed with its centre `pan` [px] (right, down) off the centre of a W × H frame;
/// bilinear, black outside the photo. Also the warp of the scenes of `scenes.rs`.
pub(crate) fn warp(src: &RgbImage, scale: f64, pan: [f64; 2], roll: f64) -> RgbImage {
    let (s, c) = roll.to_radians().sin_cos();
    let (scx, scy) = (f64::from(src.width) / 2.0, f64::from(src.height) / 2.0);
    let (ocx, ocy) = (f64::from(W) / 2.0 + pan[0], f64::from(H) / 2.0 + pan[1]);
    let mut out = RgbImage::black(W, H);
    let sw = src.width as usize;
    let at = |x: i64, y: i64, ch: usize| -> f64 {
        if x < 0 || y < 0 || x >= i64::from(src.width) || y >= i64::from(src.height) {
            0.0
        } else {
            f64::from(src.data[(y as usize * sw + x as usize) * 3 + ch])
        }
    };
    for y in 0..H {
        for x in 0..W {
            // Output pixel centre → source position: undo the pan; rotate by +roll, the inverse
            // of the forward rotation by −roll in y-down coordinates (counter-clockwise on
            // screen); undo the scale.
            let (dx, dy) = (f64::from(x) + 0.5 - ocx, f64::from(y) + 0.5 - ocy);
            let (rx, ry) = (c * dx - s * dy, s * dx + c * dy);
            let (sx, sy) = (scx + rx / scale - 0.5, scy + ry / scale - 0.5);
            let (x0, y0) = (sx.floor(), sy.floor());
            let (fx, fy) = (sx - x0, sy - y0);
            let (x0, y0) = (x0 as i64, y0 as i64);
            let o = ((y * W + x) * 3) as usize;
            for ch in 0..3 {
                let v = (1.0 - fy) * ((1.0 - fx) * at(x0, y0, ch) + fx * at(x0 + 1, y0, ch))
                    + fy * ((1.0 - fx) * at(x0, y0 + 1, ch) + fx * at(x0 + 1, y0 + 1, ch));
                out.data[o + ch] = v.round().clamp(0.0, 255.0) as u8;
            }
        }
    }
    out
}

/// 64-bit FNV-1a of `data`: the frame checksum the fixture records.
pub(crate) fn fnv1a(data: &[u8]) -> u64 {
    data.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}
