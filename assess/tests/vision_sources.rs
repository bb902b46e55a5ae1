//! Video-file, webcam and image-folder frame sources and the MJPG video sink (feature
//! `vision`): files written with OpenCV (or the sink) into a temporary folder and read back.
#![cfg(feature = "vision")]

use std::path::Path;

use assess::AssessError;
use assess::vision::source::capture::{
    DepthSequence, VideoFileOptions, VideoFileSource, VideoSink, WebcamOptions, WebcamSource,
    write_depth_png,
};
use assess::vision::source::folder::{ImageFolderOptions, ImageFolderSource};
use assess::vision::{CameraFrame, DepthImage, FrameSource, Intrinsics, RgbImage};
use opencv::core::{self, Mat, Rect, Scalar, Size};
use opencv::prelude::*;
use opencv::{imgcodecs, imgproc, videoio};

const W: i32 = 160;
const H: i32 = 120;

/// A BGR frame: a pure-red 40 x 40 patch at the top left, pure blue at the top right, the rest
/// grey at a level that changes with k.
fn bgr_frame(k: i32) -> Mat {
    let grey = f64::from(60 + 10 * k);
    let mut m =
        Mat::new_rows_cols_with_default(H, W, core::CV_8UC3, Scalar::all(grey)).expect("mat");
    imgproc::rectangle(
        &mut m,
        Rect::new(0, 0, 40, 40),
        Scalar::new(0.0, 0.0, 255.0, 0.0), // B, G, R
        imgproc::FILLED,
        imgproc::LINE_8,
        0,
    )
    .expect("red");
    imgproc::rectangle(
        &mut m,
        Rect::new(W - 40, 0, 40, 40),
        Scalar::new(255.0, 0.0, 0.0, 0.0),
        imgproc::FILLED,
        imgproc::LINE_8,
        0,
    )
    .expect("blue");
    m
}

fn pixel(f: &CameraFrame, u: u32, v: u32) -> [u8; 3] {
    let i = ((v * f.color.width + u) * 3) as usize;
    [f.color.data[i], f.color.data[i + 1], f.color.data[i + 2]]
}

fn write_video(path: &Path, frames: i32, fps: f64) {
    let fourcc = videoio::VideoWriter::fourcc('M', 'J', 'P', 'G').expect("fourcc");
    let mut w = videoio::VideoWriter::new(
        path.to_str().expect("utf-8"),
        fourcc,
        fps,
        Size::new(W, H),
        true,
    )
    .expect("writer");
    assert!(
        w.is_opened().expect("is_opened"),
        "MJPG writer not available"
    );
    for k in 0..frames {
        w.write(&bgr_frame(k)).expect("write");
    }
    w.release().expect("release");
}

/// A depth folder: `depth.toml` plus `NNNNNN.png` (or the given stems) with value
/// 1000 + 100 k everywhere except 0 (no depth) in the top-left 10 x 10 px.
fn write_depth(dir: &Path, stems: &[String], intrinsics: bool) {
    std::fs::create_dir_all(dir).expect("depth dir");
    let mut toml = String::from("scale_m = 0.001\n");
    if intrinsics {
        toml.push_str(
            "image_size_px = [160, 120]\nintrinsics = { fx_px = 150.0, fy_px = 151.0, cx_px = 79.5, cy_px = 60.5 }\n",
        );
    }
    std::fs::write(dir.join("depth.toml"), toml).expect("depth.toml");
    for (k, stem) in stems.iter().enumerate() {
        let mut data = vec![1000 + 100 * k as u16; (W * H) as usize];
        for v in 0..10 {
            for u in 0..10 {
                data[v * W as usize + u] = 0;
            }
        }
        let img = DepthImage {
            width: W as u32,
            height: H as u32,
            data,
            scale_m: 0.001,
        };
        write_depth_png(&img, dir.join(format!("{stem}.png"))).expect("depth png");
    }
}

fn read_all(src: &mut dyn FrameSource) -> Vec<CameraFrame> {
    let mut out = Vec::new();
    while let Some(f) = src.next_frame().expect("frame") {
        out.push(f);
        assert!(out.len() < 1000, "runaway source");
    }
    out
}

fn assert_red_and_blue(f: &CameraFrame, tolerance: u8) {
    let red = pixel(f, 20, 20);
    let blue = pixel(f, W as u32 - 20, 20);
    assert!(
        red[0] >= 255 - tolerance && red[1] <= tolerance && red[2] <= tolerance,
        "frame {}: red patch reads {red:?} (RGB expected)",
        f.index
    );
    assert!(
        blue[2] >= 255 - tolerance && blue[0] <= tolerance && blue[1] <= tolerance,
        "frame {}: blue patch reads {blue:?}",
        f.index
    );
}

#[test]
fn video_file_reads_back_sizes_colours_and_times() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("clip.avi");
    write_video(&path, 10, 25.0);
    let mut src = VideoFileSource::open(&path, VideoFileOptions::default()).expect("open");
    assert!(!src.has_depth());
    assert_eq!(src.fps(), 25.0);
    assert!(src.describe().contains("clip.avi"), "{}", src.describe());
    let frames = read_all(&mut src);
    assert_eq!(frames.len(), 10);
    assert!(src.next_frame().expect("after the end").is_none());
    for (k, f) in frames.iter().enumerate() {
        assert_eq!(f.index, k as u64);
        assert_eq!((f.color.width, f.color.height), (W as u32, H as u32));
        assert!(f.color.is_well_formed());
        assert!(f.depth.is_none());
        assert_red_and_blue(f, 40); // MJPG is lossy
        // Grey level 60 + 10 k in the bottom half.
        let g = pixel(f, 80, 100);
        assert!(
            g.iter()
                .all(|&c| (i32::from(c) - (60 + 10 * k as i32)).abs() <= 4),
            "{g:?}"
        );
        // Default intrinsics: 69 degrees horizontal field of view, centred.
        assert_eq!(f.intrinsics, Intrinsics::from_hfov(160, 120, 69.0));
    }
    for pair in frames.windows(2) {
        let dt = pair[1].t - pair[0].t;
        assert!((dt - 0.04).abs() < 1e-3, "dt {dt}");
    }
    assert!(frames[0].t.abs() < 1e-9, "first frame at {}", frames[0].t);
}

#[test]
fn video_file_with_depth_sequence_and_intrinsics() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("clip.avi");
    write_video(&path, 6, 30.0);
    let stems: Vec<String> = (0..6).map(|k| format!("{k:06}")).collect();
    write_depth(&dir.path().join("depth"), &stems, true);
    let opts = VideoFileOptions {
        depth: Some(dir.path().join("depth")),
        ..VideoFileOptions::default()
    };
    let mut src = VideoFileSource::open(&path, opts.clone()).expect("open");
    assert!(src.has_depth());
    let frames = read_all(&mut src);
    assert_eq!(frames.len(), 6);
    for (k, f) in frames.iter().enumerate() {
        let d = f.depth.as_ref().expect("depth");
        assert_eq!((d.width, d.height), (160, 120));
        assert_eq!(d.depth_m(5, 5), None, "0 is no depth");
        let z = d.depth_m(100, 80).expect("depth");
        assert!((z - (1.0 + 0.1 * k as f64)).abs() < 1e-9, "{z}");
        assert_eq!(f.intrinsics.fx, 150.0);
        assert_eq!(f.intrinsics.cy, 60.5);
    }
    // Given intrinsics take precedence, and must match the frame size.
    let given = Intrinsics::from_hfov(160, 120, 50.0);
    let mut src = VideoFileSource::open(
        &path,
        VideoFileOptions {
            intrinsics: Some(given),
            ..opts.clone()
        },
    )
    .expect("open");
    assert_eq!(
        src.next_frame().expect("frame").expect("some").intrinsics,
        given
    );
    let mut src = VideoFileSource::open(
        &path,
        VideoFileOptions {
            intrinsics: Some(Intrinsics::from_hfov(640, 480, 50.0)),
            ..opts.clone()
        },
    )
    .expect("open");
    let msg = src.next_frame().expect_err("size mismatch").to_string();
    assert!(
        msg.contains("640 x 480") && msg.contains("160 x 120"),
        "{msg}"
    );
    // A missing depth PNG is an error naming it, at that frame.
    std::fs::remove_file(dir.path().join("depth/000003.png")).expect("rm");
    let mut src = VideoFileSource::open(&path, opts).expect("open");
    for _ in 0..3 {
        src.next_frame().expect("frames 0-2").expect("some");
    }
    let msg = src.next_frame().expect_err("missing").to_string();
    assert!(
        msg.contains("000003.png") && msg.contains("no such depth image file"),
        "{msg}"
    );
}

#[test]
fn broken_video_files_are_errors_not_panics() {
    let dir = tempfile::tempdir().expect("temp dir");
    let good = dir.path().join("clip.avi");
    write_video(&good, 5, 25.0);
    let bytes = std::fs::read(&good).expect("read");

    let empty = dir.path().join("empty.avi");
    std::fs::write(&empty, b"").expect("write");
    let err = VideoFileSource::open(&empty, VideoFileOptions::default()).expect_err("empty");
    assert!(matches!(err, AssessError::Source { .. }));
    assert!(err.to_string().contains("empty.avi"), "{err}");

    let missing = VideoFileSource::open(dir.path().join("nope.avi"), VideoFileOptions::default())
        .expect_err("missing");
    assert!(missing.to_string().contains("nope.avi"), "{missing}");

    let garbage = dir.path().join("garbage.avi");
    std::fs::write(&garbage, vec![0x5a; 4096]).expect("write");
    assert_unreadable(&garbage);

    // Only the first 200 bytes (the RIFF header, no frame).
    let truncated = dir.path().join("truncated.avi");
    std::fs::write(&truncated, &bytes[..200]).expect("write");
    assert_unreadable(&truncated);

    // Cut in the middle: whatever decodes is returned, then the stream ends; no panic.
    let half = dir.path().join("half.avi");
    std::fs::write(&half, &bytes[..bytes.len() / 2]).expect("write");
    if let Ok(mut src) = VideoFileSource::open(&half, VideoFileOptions::default()) {
        let mut n = 0;
        while let Ok(Some(_)) = src.next_frame() {
            n += 1;
            assert!(n <= 5);
        }
    }
}

/// Opening fails, or the first frame does; either way a source error naming the file.
fn assert_unreadable(path: &Path) {
    let err = match VideoFileSource::open(path, VideoFileOptions::default()) {
        Err(e) => e,
        Ok(mut src) => src.next_frame().expect_err("no decodable frame"),
    };
    assert!(matches!(err, AssessError::Source { .. }), "{err:?}");
    let name = path.file_name().and_then(|n| n.to_str()).expect("name");
    assert!(err.to_string().contains(name), "{err}");
}

#[test]
fn image_folder_reads_sorted_images_with_depth() {
    let dir = tempfile::tempdir().expect("temp dir");
    let images = dir.path().join("images");
    std::fs::create_dir_all(images.join("subfolder")).expect("dirs");
    // Written out of order; one JPEG among PNGs; a non-image file and a subfolder to ignore.
    for (k, ext) in [(2, "png"), (0, "png"), (1, "JPG"), (3, "png")] {
        let p = images.join(format!("{k:06}.{ext}"));
        assert!(
            imgcodecs::imwrite(
                p.to_str().expect("utf-8"),
                &bgr_frame(k),
                &core::Vector::new()
            )
            .expect("imwrite")
        );
    }
    std::fs::write(images.join("notes.txt"), "not an image").expect("txt");
    let stems: Vec<String> = (0..4).map(|k| format!("{k:06}")).collect();
    write_depth(&dir.path().join("depth"), &stems, false);

    let opts = ImageFolderOptions {
        fps: 10.0,
        depth: Some(dir.path().join("depth")),
        ..ImageFolderOptions::default()
    };
    let mut src = ImageFolderSource::open(&images, opts).expect("open");
    assert_eq!(src.files().len(), 4);
    assert!(src.has_depth());
    let frames = read_all(&mut src);
    assert_eq!(frames.len(), 4);
    for (k, f) in frames.iter().enumerate() {
        assert_eq!(f.index, k as u64);
        assert!((f.t - k as f64 / 10.0).abs() < 1e-12);
        assert_eq!((f.color.width, f.color.height), (160, 120));
        let tolerance = if k == 1 { 40 } else { 0 }; // the JPEG
        assert_red_and_blue(f, tolerance);
        let g = pixel(f, 80, 100);
        assert!(
            (i32::from(g[0]) - (60 + 10 * k as i32)).abs() <= 3,
            "order: {g:?}"
        );
        let d = f.depth.as_ref().expect("depth");
        assert_eq!(d.depth_m(100, 80), Some(1.0 + 0.1 * k as f64));
        assert_eq!(d.depth_m(0, 0), None);
        assert_eq!(f.intrinsics, Intrinsics::from_hfov(160, 120, 69.0));
    }
    for pair in frames.windows(2) {
        assert!(pair[1].t > pair[0].t);
    }
    assert!(src.next_frame().expect("end").is_none());
}

#[test]
fn image_folder_errors_name_the_file_and_do_not_panic() {
    let dir = tempfile::tempdir().expect("temp dir");
    let images = dir.path().join("images");
    std::fs::create_dir_all(&images).expect("dir");
    let err = ImageFolderSource::open(&images, ImageFolderOptions::default()).expect_err("empty");
    assert!(err.to_string().contains("no image files"), "{err}");
    let err = ImageFolderSource::open(dir.path().join("nope"), ImageFolderOptions::default())
        .expect_err("missing");
    assert!(err.to_string().contains("nope"), "{err}");

    for k in 0..3 {
        let p = images.join(format!("{k:06}.png"));
        imgcodecs::imwrite(
            p.to_str().expect("utf-8"),
            &bgr_frame(k),
            &core::Vector::new(),
        )
        .expect("imwrite");
    }
    // Truncate the middle image and make an empty "image".
    let mid = images.join("000001.png");
    let bytes = std::fs::read(&mid).expect("read");
    std::fs::write(&mid, &bytes[..bytes.len() / 3]).expect("truncate");
    std::fs::write(images.join("000003.png"), b"").expect("empty");

    let mut src = ImageFolderSource::open(&images, ImageFolderOptions::default()).expect("open");
    assert_eq!(src.next_frame().expect("0").expect("some").index, 0);
    let err = src.next_frame().expect_err("truncated");
    assert!(matches!(err, AssessError::Source { .. }));
    assert!(err.to_string().contains("000001.png"), "{err}");
    // The source moves on past a bad frame.
    assert_eq!(src.next_frame().expect("2").expect("some").index, 2);
    let err = src.next_frame().expect_err("empty file");
    assert!(err.to_string().contains("000003.png"), "{err}");
    assert!(src.next_frame().expect("end").is_none());

    // A depth image of the wrong size names the depth file.
    let depth = dir.path().join("depth");
    std::fs::create_dir_all(&depth).expect("dir");
    std::fs::write(depth.join("depth.toml"), "scale_m = 0.001\n").expect("toml");
    let small = DepthImage {
        width: 8,
        height: 8,
        data: vec![1; 64],
        scale_m: 0.001,
    };
    write_depth_png(&small, depth.join("000000.png")).expect("png");
    let opts = ImageFolderOptions {
        depth: Some(depth.clone()),
        ..ImageFolderOptions::default()
    };
    let mut src = ImageFolderSource::open(&images, opts).expect("open");
    let msg = src.next_frame().expect_err("size").to_string();
    assert!(msg.contains("000000.png") && msg.contains("8 x 8"), "{msg}");
}

#[test]
fn depth_toml_is_validated() {
    let dir = tempfile::tempdir().expect("temp dir");
    let cases = [
        ("scale_m = 0.0\n", "scale_m"),
        (
            "scale_m = 0.001\nintrinsics = { fx_px = 1.0, fy_px = 1.0, cx_px = 0.0, cy_px = 0.0 }\n",
            "image_size_px",
        ),
        (
            "scale_m = 0.001\nimage_size_px = [160, 120]\nintrinsics = { fx_px = -1.0, fy_px = 1.0, cx_px = 0.0, cy_px = 0.0 }\n",
            "intrinsics.fx_px",
        ),
        ("scale = 0.001\n", "scale"),
    ];
    for (text, key) in cases {
        std::fs::write(dir.path().join("depth.toml"), text).expect("write");
        let msg = DepthSequence::open(dir.path()).expect_err(text).to_string();
        assert!(
            msg.contains(key) && msg.contains("depth.toml"),
            "{text}: {msg}"
        );
    }
    std::fs::remove_file(dir.path().join("depth.toml")).expect("rm");
    let msg = DepthSequence::open(dir.path())
        .expect_err("no toml")
        .to_string();
    assert!(msg.contains("depth.toml"), "{msg}");
}

#[test]
fn depth_png_round_trips_16_bit_values() {
    let dir = tempfile::tempdir().expect("temp dir");
    std::fs::write(dir.path().join("depth.toml"), "scale_m = 0.0001\n").expect("toml");
    let data: Vec<u16> = (0..64u16).map(|i| i * 1000 + 7).collect();
    let img = DepthImage {
        width: 16,
        height: 4,
        data: data.clone(),
        scale_m: 0.0001,
    };
    write_depth_png(&img, dir.path().join("000000.png")).expect("write");
    let seq = DepthSequence::open(dir.path()).expect("open");
    let back = seq.read(&seq.frame_path(0), 16, 4).expect("read");
    assert_eq!(back.data, data);
    assert_eq!(back.depth_m(1, 0), Some(1007.0 * 0.0001));
    // An 8-bit PNG is not depth.
    let p = dir.path().join("000001.png");
    imgcodecs::imwrite(
        p.to_str().expect("utf-8"),
        &bgr_frame(0),
        &core::Vector::new(),
    )
    .expect("imwrite");
    let msg = seq.read(&p, 160, 120).expect_err("8-bit").to_string();
    assert!(msg.contains("16-bit"), "{msg}");
}

#[test]
fn a_missing_webcam_is_an_error() {
    let err = WebcamSource::open(97, WebcamOptions::default()).expect_err("no /dev/video97");
    assert!(matches!(err, AssessError::Source { .. }), "{err:?}");
    assert!(err.to_string().contains("webcam 97"), "{err}");
}

/// An RGB image of `w` x `h` px: grey `level`, with a pure-red 40 x 40 patch at the top left
/// and pure blue at the top right (the RGB twin of `bgr_frame`).
fn rgb_frame(w: u32, h: u32, level: u8) -> RgbImage {
    let mut img = RgbImage::black(w, h);
    for v in 0..h {
        for u in 0..w {
            let px = if v < 40 && u < 40 {
                [255, 0, 0]
            } else if v < 40 && u >= w - 40 {
                [0, 0, 255]
            } else {
                [level; 3]
            };
            let i = ((v * w + u) * 3) as usize;
            img.data[i..i + 3].copy_from_slice(&px);
        }
    }
    img
}

#[test]
fn video_sink_writes_mjpg_that_reads_back() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("view.AVI");
    let mut sink = VideoSink::create(&path, 20.0).expect("create");
    assert_eq!(sink.size(), None);
    assert!(!path.exists(), "nothing is written before the first frame");
    for k in 0..4u8 {
        sink.write(&rgb_frame(W as u32, H as u32, 60 + 10 * k))
            .expect("write");
    }
    assert_eq!(sink.size(), Some((W as u32, H as u32)));
    // A frame of another size is refused, names the file, and is not written.
    let err = sink.write(&rgb_frame(80, 60, 0)).expect_err("size");
    assert!(matches!(err, AssessError::Source { .. }), "{err:?}");
    let msg = err.to_string();
    assert!(
        msg.contains("view.AVI") && msg.contains("80 x 60") && msg.contains("160 x 120"),
        "{msg}"
    );
    assert_eq!(sink.frames(), 4);
    sink.finish().expect("finish");

    let mut src = VideoFileSource::open(&path, VideoFileOptions::default()).expect("open");
    assert_eq!(src.fps(), 20.0);
    let frames = read_all(&mut src);
    assert_eq!(frames.len(), 4);
    for (k, f) in frames.iter().enumerate() {
        assert_eq!((f.color.width, f.color.height), (W as u32, H as u32));
        // RGB in, RGB out (no channel swap); MJPG is lossy.
        assert_red_and_blue(f, 40);
        let g = pixel(f, 80, 100);
        assert!(
            g.iter()
                .all(|&c| (i32::from(c) - (60 + 10 * k as i32)).abs() <= 4),
            "frame {k}: {g:?}"
        );
    }
    for pair in frames.windows(2) {
        assert!((pair[1].t - pair[0].t - 0.05).abs() < 1e-3);
    }
}

#[test]
fn video_sink_refuses_other_containers_and_writes_nothing_without_frames() {
    let dir = tempfile::tempdir().expect("temp dir");
    let err = VideoSink::create(dir.path().join("view.mp4"), 30.0).expect_err("mp4");
    assert!(matches!(err, AssessError::Source { .. }), "{err:?}");
    assert!(err.to_string().contains("view.mp4"), "{err}");
    let err = VideoSink::create(dir.path().join("view.avi"), 0.0).expect_err("fps");
    assert!(err.to_string().contains("fps"), "{err}");
    let path = dir.path().join("empty.avi");
    VideoSink::create(&path, 30.0)
        .expect("create")
        .finish()
        .expect("finish");
    assert!(!path.exists());
    // An unwritable place is an error naming the file at the first frame.
    let path = dir.path().join("no-such-folder/view.avi");
    let mut sink = VideoSink::create(&path, 30.0).expect("create");
    let err = sink.write(&rgb_frame(64, 48, 0)).expect_err("no folder");
    assert!(err.to_string().contains("no-such-folder"), "{err}");
}

/// Photos of three sizes in one folder.
fn mixed_size_folder(dir: &Path) -> std::path::PathBuf {
    let images = dir.join("photos");
    std::fs::create_dir_all(&images).expect("dir");
    for (k, (w, h)) in [(160, 120), (96, 128), (160, 120)].into_iter().enumerate() {
        let p = images.join(format!("{k:06}.png"));
        let m =
            Mat::new_rows_cols_with_default(h, w, core::CV_8UC3, Scalar::all(90.0)).expect("mat");
        assert!(
            imgcodecs::imwrite(p.to_str().expect("utf-8"), &m, &core::Vector::new())
                .expect("imwrite")
        );
    }
    images
}

#[test]
fn image_folder_of_mixed_sizes_gets_intrinsics_per_image() {
    let dir = tempfile::tempdir().expect("temp dir");
    let images = mixed_size_folder(dir.path());
    let opts = ImageFolderOptions {
        hfov_deg: 60.0,
        ..ImageFolderOptions::default()
    };
    let mut src = ImageFolderSource::open(&images, opts).expect("open");
    assert!(!src.fixed_size());
    let frames = read_all(&mut src);
    let sizes: Vec<(u32, u32)> = frames
        .iter()
        .map(|f| (f.color.width, f.color.height))
        .collect();
    assert_eq!(sizes, [(160, 120), (96, 128), (160, 120)]);
    for f in &frames {
        assert_eq!(
            f.intrinsics,
            Intrinsics::from_hfov(f.color.width, f.color.height, 60.0)
        );
    }
}

#[test]
fn image_folder_with_fixed_intrinsics_refuses_a_size_change() {
    let dir = tempfile::tempdir().expect("temp dir");
    let images = mixed_size_folder(dir.path());
    // Given intrinsics.
    let given = Intrinsics::from_hfov(160, 120, 50.0);
    let opts = ImageFolderOptions {
        intrinsics: Some(given),
        ..ImageFolderOptions::default()
    };
    let mut src = ImageFolderSource::open(&images, opts).expect("open");
    assert!(src.fixed_size());
    assert_eq!(
        src.next_frame().expect("0").expect("some").intrinsics,
        given
    );
    let err = src.next_frame().expect_err("size change");
    assert!(matches!(err, AssessError::Source { .. }), "{err:?}");
    let msg = err.to_string();
    assert!(
        msg.contains("000001.png") && msg.contains("96 x 128") && msg.contains("160 x 120"),
        "{msg}"
    );
    // The source moves on; the third image has the first one's size.
    assert_eq!(
        src.next_frame().expect("2").expect("some").intrinsics,
        given
    );

    // Intrinsics from a depth sequence.
    let stems: Vec<String> = (0..3).map(|k| format!("{k:06}")).collect();
    write_depth(&dir.path().join("depth"), &stems, true);
    let opts = ImageFolderOptions {
        depth: Some(dir.path().join("depth")),
        ..ImageFolderOptions::default()
    };
    let mut src = ImageFolderSource::open(&images, opts).expect("open");
    assert!(src.fixed_size());
    assert_eq!(
        src.next_frame().expect("0").expect("some").intrinsics.fx,
        150.0
    );
    let msg = src.next_frame().expect_err("size change").to_string();
    assert!(
        msg.contains("000001.png") && msg.contains("96 x 128"),
        "{msg}"
    );
}
