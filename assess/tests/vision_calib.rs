//! Board calibration and the extrinsics file (feature `vision`).
//!
//! The synthetic camera images are made independently of `calibrate`'s own pose code: the
//! printed board image is mapped to board coordinates with the convention the module documents
//! (origin at the bottom-left corner of the printed board, x right, y up, z out of the page),
//! then warped into a pinhole camera at a known pose by the plane homography K [r1 r2 t].
#![cfg(feature = "vision")]

use std::path::PathBuf;

use assess::vision::calib::{
    self, BoardPlacement, BoardSpec, CalibrationInfo, ExtrinsicsFile, render_board,
};
use assess::vision::{Extrinsics, Intrinsics, RgbImage};
use assess::{AssessError, Vec3, Workspace};
use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use opencv::core::{self, Mat, Scalar, Size, Vec3b};
use opencv::prelude::*;
use opencv::{imgcodecs, imgproc};

fn intrinsics() -> Intrinsics {
    Intrinsics {
        width: 1280,
        height: 720,
        fx: 910.0,
        fy: 905.0,
        cx: 652.3,
        cy: 355.8,
    }
}

/// workspace ← camera for a camera at `eye` looking at `target` (image x to the right of the
/// view, image y downwards in the world).
fn look_at(eye: Vec3, target: Vec3) -> Isometry3<f64> {
    let z = (target - eye).normalize();
    let x = z.cross(&Vec3::z()).normalize();
    let y = z.cross(&x);
    let r = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, z]));
    Isometry3::from_parts(
        Translation3::from(eye),
        UnitQuaternion::from_rotation_matrix(&r),
    )
}

/// The camera image of the board lying at board ← world identity, seen from
/// `world_from_camera`; grey background.
fn synthetic_image(board: &BoardSpec, world_from_camera: &Isometry3<f64>) -> RgbImage {
    // 50 px per 40 mm square, 5 mm margin (no label).
    let dpi = 50.0 / board.square_m() * 0.0254;
    let print = render_board(board, dpi, 0.005).expect("render");
    let ppm = print.px_per_m;
    let m_px = print.margin_m * ppm;
    let (_, board_h) = board.size_m();
    // Board image pixel (centre-at-integer convention) → board plane (X, Y, 1) [m].
    let a = Matrix3::new(
        1.0 / ppm,
        0.0,
        (0.5 - m_px) / ppm,
        0.0,
        -1.0 / ppm,
        board_h + (m_px - 0.5) / ppm,
        0.0,
        0.0,
        1.0,
    );
    let k = intrinsics();
    let km = Matrix3::new(k.fx, 0.0, k.cx, 0.0, k.fy, k.cy, 0.0, 0.0, 1.0);
    let cam_from_board = world_from_camera.inverse().to_homogeneous();
    let rt = Matrix3::from_columns(&[
        cam_from_board.fixed_view::<3, 1>(0, 0).into_owned(),
        cam_from_board.fixed_view::<3, 1>(0, 1).into_owned(),
        cam_from_board.fixed_view::<3, 1>(0, 3).into_owned(),
    ]);
    let h = km * rt * a;
    let rows: Vec<[f64; 3]> = (0..3).map(|r| [h[(r, 0)], h[(r, 1)], h[(r, 2)]]).collect();
    let hm = Mat::from_slice_2d(&rows).expect("homography");
    let src = Mat::new_rows_cols_with_bytes::<Vec3b>(
        print.image.height as i32,
        print.image.width as i32,
        &print.image.data,
    )
    .expect("view");
    let mut dst = Mat::default();
    imgproc::warp_perspective(
        &src,
        &mut dst,
        &hm,
        Size::new(k.width as i32, k.height as i32),
        imgproc::INTER_LINEAR,
        core::BORDER_CONSTANT,
        Scalar::all(110.0),
    )
    .expect("warp");
    RgbImage {
        width: k.width,
        height: k.height,
        data: dst.data_bytes().expect("bytes").to_vec(),
    }
}

fn pose_error(a: &Isometry3<f64>, b: &Isometry3<f64>) -> (f64, f64) {
    let dt = (a.translation.vector - b.translation.vector).norm();
    let dr = a.rotation.angle_to(&b.rotation).to_degrees();
    (dt, dr)
}

fn oblique_camera() -> Isometry3<f64> {
    // 0.55 m above the table, 0.45 m in front of the board, looking at its centre.
    look_at(Vec3::new(0.13, -0.42, 0.55), Vec3::new(0.1, 0.14, 0.0))
}

#[test]
fn recovers_a_known_pose_from_a_synthetic_image() {
    let board = BoardSpec::default();
    for (name, truth) in [
        ("oblique", oblique_camera()),
        (
            "steep, from the side",
            look_at(Vec3::new(0.45, 0.05, 0.62), Vec3::new(0.08, 0.15, 0.0)),
        ),
    ] {
        let image = synthetic_image(&board, &truth);
        let cal = calib::calibrate(&board, &image, &intrinsics()).expect(name);
        let (dt, dr) = pose_error(&cal.extrinsics.world_from_camera, &truth);
        eprintln!(
            "{name}: {:.3} mm, {dr:.4} deg, rms {:.3} px",
            dt * 1e3,
            cal.reprojection_rms_px
        );
        assert!(dt < 0.002, "{name}: translation error {:.2} mm", dt * 1e3);
        assert!(dr < 0.3, "{name}: rotation error {dr:.3} deg");
        assert_eq!(
            cal.detection.corners.len(),
            24,
            "{name}: all corners in view"
        );
        assert!(
            cal.detection.markers >= 15,
            "{name}: {} markers",
            cal.detection.markers
        );
        assert!(
            cal.reprojection_rms_px < 0.5,
            "{name}: rms {}",
            cal.reprojection_rms_px
        );
        let (dt, dr) = pose_error(&cal.board_from_camera, &cal.extrinsics.world_from_camera);
        assert!(dt < 1e-12 && dr < 1e-9, "identity placement");
    }
}

#[test]
fn placement_moves_the_workspace_frame() {
    let truth = oblique_camera();
    let image = synthetic_image(&BoardSpec::default(), &truth);
    let placement = BoardPlacement {
        origin_m: Vec3::new(0.5, -0.2, 0.75),
        yaw_rad: 90f64.to_radians(),
    };
    let board = BoardSpec::default().with_placement(placement);
    let cal = calib::calibrate(&board, &image, &intrinsics()).expect("calibrate");
    let expected = placement.world_from_board() * truth;
    let (dt, dr) = pose_error(&cal.extrinsics.world_from_camera, &expected);
    assert!(dt < 0.002 && dr < 0.3, "{dt} m, {dr} deg");
    // The board origin (world (0.5, -0.2, 0.75)) is seen where the unplaced origin was.
    let cam = cal.extrinsics.world_from_camera.inverse();
    let seen = intrinsics()
        .project(&(cam * Point3::new(0.5, -0.2, 0.75)))
        .expect("in front");
    let direct = intrinsics()
        .project(&(truth.inverse() * Point3::origin()))
        .expect("in front");
    assert!((seen.0 - direct.0).abs() < 1.0 && (seen.1 - direct.1).abs() < 1.0);
}

#[test]
fn an_image_without_the_board_is_a_clear_error() {
    let k = intrinsics();
    let mut image = RgbImage::black(k.width, k.height);
    for (i, px) in image.data.iter_mut().enumerate() {
        *px = ((i * 7919) % 251) as u8 / 2 + 60; // texture, no markers
    }
    let err = calib::calibrate(&BoardSpec::default(), &image, &k).expect_err("no board");
    let msg = err.to_string();
    assert!(matches!(err, AssessError::Vision { .. }), "{err:?}");
    assert!(msg.contains("no DICT_4X4_50 marker found"), "{msg}");
}

#[test]
fn too_few_corners_is_refused_with_the_counts() {
    let truth = oblique_camera();
    let mut image = synthetic_image(&BoardSpec::default(), &truth);
    // Grey out everything right of the image centre: part of the board stays visible.
    let w = image.width as usize;
    for (i, px) in image.data.chunks_exact_mut(3).enumerate() {
        if i % w > w / 2 {
            px.copy_from_slice(&[110, 110, 110]);
        }
    }
    let all = BoardSpec::from_toml_str(
        "squares_x = 5\nsquares_y = 7\nsquare_m = 0.04\nmarker_m = 0.03\n\
         dictionary = \"DICT_4X4_50\"\nmin_corners = 24\n",
    )
    .expect("board");
    let found = calib::detect_board(&all, &image, &intrinsics())
        .expect("some markers")
        .corners
        .len();
    assert!((1..24).contains(&found), "{found} corners");
    let msg = calib::calibrate(&all, &image, &intrinsics())
        .expect_err("too few")
        .to_string();
    assert!(
        msg.contains(&format!("only {found} board corners found")) && msg.contains("at least 24"),
        "{msg}"
    );
}

#[test]
fn intrinsics_of_another_size_are_refused() {
    let image = RgbImage::black(640, 480);
    let err = calib::calibrate(&BoardSpec::default(), &image, &intrinsics()).expect_err("size");
    assert!(err.to_string().contains("1280 x 720"), "{err}");
}

#[test]
fn the_printed_board_has_its_size_and_is_detected() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("board.png");
    let board = BoardSpec::default();
    let print = calib::write_board_png(&board, &path, 300.0, 0.01).expect("write");
    // 40 mm at 300 dpi = 472.4 px, rounded to 472 px.
    assert!((print.px_per_m - 472.0 / 0.04).abs() < 1e-9);
    assert!((print.paper_m.0 - 0.22).abs() < 1e-3 && (print.paper_m.1 - 0.30).abs() < 1e-3);
    let bytes = std::fs::read(&path).expect("read");
    let phys = bytes
        .windows(4)
        .position(|w| w == b"pHYs")
        .expect("pHYs chunk");
    let ppm = u32::from_be_bytes(bytes[phys + 4..phys + 8].try_into().expect("4 bytes"));
    assert_eq!(ppm, 11_800);
    let mat =
        imgcodecs::imread(path.to_str().expect("utf-8"), imgcodecs::IMREAD_COLOR).expect("imread");
    assert_eq!(
        (mat.cols(), mat.rows()),
        (print.image.width as i32, print.image.height as i32)
    );
    assert_eq!(print.image.width, 5 * 472 + 2 * 118);
    // The print itself, seen head-on, shows every corner.
    let img = &print.image;
    let k = Intrinsics::from_hfov(img.width, img.height, 60.0);
    let det = calib::detect_board(&board, img, &k).expect("detect");
    assert_eq!(det.corners.len(), 24);
    assert_eq!(det.markers, 17);
    // Corner 0 (OpenCV numbers from the top-left) is at (40 mm, 240 mm) in the board frame: one
    // square right of and below the top-left board corner on the page.
    assert!((board.corner_points()[0] - Vec3::new(0.04, 0.24, 0.0)).norm() < 1e-12);
    let (_, u, v) = *det.corners.iter().find(|c| c.0 == 0).expect("corner 0");
    let s = 472.0;
    let (u0, v0) = (118.0 + s - 0.5, 118.0 + s - 0.5);
    assert!((u - u0).abs() < 1.0 && (v - v0).abs() < 1.0, "({u}, {v})");
}

#[test]
fn check_image_draws_areas_and_board() {
    let truth = oblique_camera();
    let board = BoardSpec::default();
    let image = synthetic_image(&board, &truth);
    let cal = calib::calibrate(&board, &image, &intrinsics()).expect("calibrate");
    let ws = Workspace::from_toml_str(
        r#"
        [[area]]
        name = "assembly"
        role = "assembly"
        min_m = [0.0, 0.0, 0.0]
        max_m = [0.2, 0.28, 0.1]
        "#,
    )
    .expect("workspace");
    let out = calib::check_image(
        &image,
        &intrinsics(),
        &cal.extrinsics,
        &board,
        Some(&ws),
        Some(&cal),
    )
    .expect("check");
    assert_eq!((out.width, out.height), (image.width, image.height));
    // The projected top-front-right corner of the area box lies on a cyan edge.
    let p = intrinsics()
        .project(&(truth.inverse() * Point3::new(0.2, 0.0, 0.1)))
        .expect("in front");
    let (u, v) = (p.0.round() as usize, p.1.round() as usize);
    let px = &out.data[(v * out.width as usize + u) * 3..][..3];
    assert!(
        px[0] < 100 && px[1] > 150 && px[2] > 150,
        "{px:?} at ({u}, {v})"
    );
    let changed = out
        .data
        .iter()
        .zip(&image.data)
        .filter(|(a, b)| a != b)
        .count();
    assert!(changed > 5_000, "{changed} bytes changed");
}

fn sample_file() -> ExtrinsicsFile {
    let q = UnitQuaternion::from_euler_angles(-2.1, 0.05, 0.4);
    ExtrinsicsFile {
        extrinsics: Extrinsics {
            world_from_camera: Isometry3::from_parts(Translation3::new(0.13, -0.42, 0.55), q),
        },
        info: Some(CalibrationInfo {
            board: BoardSpec::default().to_string(),
            source: "image board.jpg".into(),
            date: "2026-05-01T10:00:00Z".into(),
            reprojection_rms_px: 0.213,
            corners: 24,
            intrinsics: intrinsics(),
        }),
    }
}

#[test]
fn extrinsics_file_round_trips() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("extrinsics.toml");
    let file = sample_file();
    file.save(&path).expect("save");
    let text = std::fs::read_to_string(&path).expect("read");
    assert!(
        text.contains("[extrinsics]") && text.contains("rotation_xyzw"),
        "{text}"
    );
    assert!(text.contains("image_size_px = [1280, 720]"), "{text}");
    let back = ExtrinsicsFile::load(&path).expect("load");
    let (dt, dr) = pose_error(
        &back.extrinsics.world_from_camera,
        &file.extrinsics.world_from_camera,
    );
    assert!(dt < 1e-12 && dr < 1e-9);
    assert_eq!(back.info, file.info);
    // Extrinsics alone.
    file.extrinsics.save(&path).expect("save bare");
    let bare = ExtrinsicsFile::load(&path).expect("load bare");
    assert!(bare.info.is_none());
    assert_eq!(
        Extrinsics::load(&path)
            .expect("load")
            .world_from_camera
            .translation,
        file.extrinsics.world_from_camera.translation
    );
}

#[test]
fn extrinsics_validation_names_key_and_file() {
    let parse = |s: &str| ExtrinsicsFile::from_toml_str(s);
    let ok =
        "[extrinsics]\nrotation_xyzw = [0.0, 0.0, 0.0, 1.0005]\ntranslation_m = [1.0, 2.0, 3.0]\n";
    let f = parse(ok).expect("within tolerance");
    let q = f.extrinsics.world_from_camera.rotation;
    assert!((q.coords.norm() - 1.0).abs() < 1e-12, "normalised");

    let err = parse(
        "[extrinsics]\nrotation_xyzw = [0.0, 0.0, 0.0, 1.1]\ntranslation_m = [0.0, 0.0, 0.0]\n",
    )
    .expect_err("not unit");
    match &err {
        AssessError::InvalidValue { key, rule } => {
            assert_eq!(key, "extrinsics.rotation_xyzw");
            assert!(rule.contains("1.100000"), "{rule}");
        }
        other => panic!("{other:?}"),
    }
    let err = parse(
        "[extrinsics]\nrotation_xyzw = [0.0, 0.0, 0.0, 1.0]\ntranslation_m = [nan, 0.0, 0.0]\n",
    )
    .expect_err("nan");
    assert!(
        err.to_string().contains("extrinsics.translation_m"),
        "{err}"
    );
    let err = parse("[extrinsics]\nrotation_xyzw = [0.0, 0.0, 0.0, 1.0]\n").expect_err("missing");
    assert!(
        matches!(err, AssessError::Parse { .. }) && err.to_string().contains("translation_m"),
        "{err}"
    );
    let err =
        parse("[extrinsics]\nrotation_xyzw = [0.0, 0.0, 1.0]\ntranslation_m = [0.0, 0.0, 0.0]\n")
            .expect_err("three values");
    assert!(err.to_string().contains("rotation_xyzw"), "{err}");
    let err = parse(
        "[extrinsics]\nrotation_xyzw = [0.0, 0.0, 0.0, 1.0]\ntranslation = [0.0, 0.0, 0.0]\n",
    )
    .expect_err("unknown key");
    assert!(err.to_string().contains("translation"), "{err}");

    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("bad.toml");
    std::fs::write(
        &path,
        "[extrinsics]\nrotation_xyzw = [0.5, 0.5, 0.5, 0.6]\ntranslation_m = [0.0, 0.0, 0.0]\n",
    )
    .expect("write");
    let msg = ExtrinsicsFile::load(&path).expect_err("bad").to_string();
    assert!(
        msg.contains("bad.toml") && msg.contains("extrinsics.rotation_xyzw"),
        "{msg}"
    );
    let msg = Extrinsics::load(dir.path().join("missing.toml"))
        .expect_err("missing")
        .to_string();
    assert!(msg.contains("missing.toml"), "{msg}");
}

#[test]
fn shipped_board_config_is_the_default_and_bad_boards_are_refused() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../config/board.toml");
    let board = BoardSpec::from_toml_file(&path).expect("config/board.toml");
    assert_eq!(board, BoardSpec::default());
    assert_eq!(
        board.to_string(),
        "ChArUco 5x7, 40 mm squares, 30 mm markers, DICT_4X4_50"
    );
    let base = "squares_x = 5\nsquare_m = 0.04\nmarker_m = 0.03\n";
    let cases = [
        (format!("{base}squares_y = 6\ndictionary = \"DICT_4X4_50\"\n"), "squares_y"),
        (format!("{base}squares_y = 7\ndictionary = \"DICT_9X9_50\"\n"), "dictionary"),
        (
            "squares_x = 11\nsquares_y = 11\nsquare_m = 0.04\nmarker_m = 0.03\ndictionary = \"DICT_4X4_50\"\n"
                .to_string(),
            "dictionary",
        ),
        (
            "squares_x = 5\nsquares_y = 7\nsquare_m = 0.04\nmarker_m = 0.05\ndictionary = \"DICT_4X4_50\"\n"
                .to_string(),
            "marker_m",
        ),
        (
            format!("{base}squares_y = 7\ndictionary = \"DICT_4X4_50\"\nmin_corners = 3\n"),
            "min_corners",
        ),
    ];
    for (text, key) in cases {
        match BoardSpec::from_toml_str(&text) {
            Err(AssessError::InvalidValue { key: k, .. }) => assert_eq!(k, key, "{text}"),
            other => panic!("{text}: {other:?}"),
        }
    }
}

#[test]
fn board_frame_axes_point_as_documented() {
    // The board lies flat, face up; a camera straight above it, image x along world x: the
    // board's x runs right in the image and y runs up the image (v decreasing).
    let eye = Vec3::new(0.1, 0.14, 0.6);
    let down = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[
        Vector3::x(),
        -Vector3::y(),
        -Vector3::z(),
    ]));
    let truth = Isometry3::from_parts(
        Translation3::from(eye),
        UnitQuaternion::from_rotation_matrix(&down),
    );
    let image = synthetic_image(&BoardSpec::default(), &truth);
    let cal = calib::calibrate(&BoardSpec::default(), &image, &intrinsics()).expect("calibrate");
    let c = cal.extrinsics.world_from_camera.translation.vector;
    assert!((c - eye).norm() < 0.002, "camera at {c}");
    let det = &cal.detection.corners;
    let at = |id: usize| {
        det.iter()
            .find(|c| c.0 == id)
            .map(|c| (c.1, c.2))
            .expect("corner")
    };
    let points = BoardSpec::default().corner_points();
    let (c0, c1, c4) = (at(0), at(1), at(4));
    // Corner 1 is 40 mm further along x than corner 0: to its right in the image.
    assert!((points[1] - points[0] - Vec3::new(0.04, 0.0, 0.0)).norm() < 1e-12);
    assert!(
        c1.0 > c0.0 + 40.0 && (c1.1 - c0.1).abs() < 1.0,
        "x runs right"
    );
    // Corner 4 is 40 mm lower in y than corner 0: below it in the image (y runs up).
    assert!((points[4] - points[0] - Vec3::new(0.0, -0.04, 0.0)).norm() < 1e-12);
    assert!(
        c4.1 > c0.1 + 40.0 && (c4.0 - c0.0).abs() < 1.0,
        "y runs up the image"
    );
}
