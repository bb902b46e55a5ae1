//! Camera-to-workspace calibration from a ChArUco board, and the extrinsics file.
//!
//! # The board defines the workspace frame
//!
//! A ChArUco board ([`BoardSpec`], default `config/board.toml`: 5 × 7 squares of 40 mm with
//! 30 mm `DICT_4X4_50` markers) is printed with [`write_board_png`] and laid flat, face up, on
//! the table. Its frame, as OpenCV 4.6's `aruco` module defines it and this module uses it, is:
//! - **origin**: the outer corner of the bottom-left square of the printed board (the board
//!   seen upright, as the PNG is displayed; the corner squares are black);
//! - **x**: along the bottom edge, to the right (across the `squares_x` columns);
//! - **y**: along the left edge, upwards (across the `squares_y` rows);
//! - **z**: out of the printed face, so **up** when the board lies face up on the table.
//!
//! The workspace frame is the board frame moved by the board's optional `placement` (its origin
//! [m] and yaw about z [deg] in the workspace frame); without it the board frame **is** the
//! workspace frame and areas are given relative to the board's corner, z up from the table top.
//!
//! # Calibration
//!
//! [`calibrate`]: ArUco markers are detected (`detectMarkers`), the chessboard corners between
//! them interpolated and refined to sub-pixel (`interpolateCornersCharuco`), and the camera pose
//! solved from those corners with the colour [`Intrinsics`] (`solvePnP`, IPPE for planar targets,
//! then Levenberg–Marquardt refinement). The result is [`Extrinsics`] (workspace ← camera), the
//! reprojection RMS [px] and the number of corners used. Fewer than the board's `min_corners`
//! corners is an error, as is a pose that puts the camera behind the board (a mirrored image).
//!
//! # Extrinsics file
//!
//! ```toml
//! [extrinsics]                 # world_from_camera: camera-frame points [m] → workspace frame [m]
//! rotation_xyzw = [0.0, 0.0, 0.0, 1.0]   # unit quaternion (x, y, z, w)
//! translation_m = [0.0, 0.0, 0.0]        # the camera's optical centre in the workspace frame [m]
//!
//! [calibration]                # optional: how it was obtained
//! board = "ChArUco 5x7, 40 mm squares, 30 mm markers, DICT_4X4_50"
//! source = "image board.jpg"
//! date = "2026-05-01T10:00:00Z"
//! reprojection_rms_px = 0.21
//! corners = 24
//! image_size_px = [1280, 720]
//! intrinsics = { fx_px = 910.0, fy_px = 910.0, cx_px = 640.0, cy_px = 360.0 }
//! ```
//!
//! Loading checks that every value is finite and the quaternion has unit norm within
//! [`QUATERNION_NORM_TOLERANCE`], then normalises it.

use std::fmt;
use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Point3, Quaternion, Rotation3, Translation3, UnitQuaternion, Vector3};
use opencv::aruco::{self, CharucoBoardTrait, PREDEFINED_DICTIONARY_NAME};
use opencv::core::{self, Mat, Point2f, Point3f, Ptr, Size, Vec3b, Vector};
use opencv::prelude::*;
use opencv::{calib3d, imgcodecs, imgproc};
use serde::{Deserialize, Serialize};

use super::draw::{self, Projector};
use super::frame::{Extrinsics, Intrinsics, RgbImage};
use crate::{AssessError, Result, Vec3, Workspace};

/// Largest accepted deviation of the stored quaternion's norm from 1 [-].
pub const QUATERNION_NORM_TOLERANCE: f64 = 1e-3;

/// Default `min_corners`: the fewest interpolated ChArUco corners a pose is computed from.
pub const DEFAULT_MIN_CORNERS: usize = 6;

/// An OpenCV error as [`AssessError::Vision`] for the named step.
pub(crate) fn cv_err(operation: &'static str) -> impl Fn(opencv::Error) -> AssessError {
    move |e| AssessError::Vision {
        operation,
        message: e.message,
    }
}

/// One of OpenCV's predefined ArUco dictionaries (`DICT_<bits>X<bits>_<codes>`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ArucoDictionary {
    name: &'static str,
    id: PREDEFINED_DICTIONARY_NAME,
    size: usize,
}

impl ArucoDictionary {
    const ALL: [ArucoDictionary; 16] = {
        use PREDEFINED_DICTIONARY_NAME as D;
        [
            Self::of("DICT_4X4_50", D::DICT_4X4_50, 50),
            Self::of("DICT_4X4_100", D::DICT_4X4_100, 100),
            Self::of("DICT_4X4_250", D::DICT_4X4_250, 250),
            Self::of("DICT_4X4_1000", D::DICT_4X4_1000, 1000),
            Self::of("DICT_5X5_50", D::DICT_5X5_50, 50),
            Self::of("DICT_5X5_100", D::DICT_5X5_100, 100),
            Self::of("DICT_5X5_250", D::DICT_5X5_250, 250),
            Self::of("DICT_5X5_1000", D::DICT_5X5_1000, 1000),
            Self::of("DICT_6X6_50", D::DICT_6X6_50, 50),
            Self::of("DICT_6X6_100", D::DICT_6X6_100, 100),
            Self::of("DICT_6X6_250", D::DICT_6X6_250, 250),
            Self::of("DICT_6X6_1000", D::DICT_6X6_1000, 1000),
            Self::of("DICT_7X7_50", D::DICT_7X7_50, 50),
            Self::of("DICT_7X7_100", D::DICT_7X7_100, 100),
            Self::of("DICT_7X7_250", D::DICT_7X7_250, 250),
            Self::of("DICT_7X7_1000", D::DICT_7X7_1000, 1000),
        ]
    };

    const fn of(name: &'static str, id: PREDEFINED_DICTIONARY_NAME, size: usize) -> Self {
        Self { name, id, size }
    }

    /// The dictionary by its OpenCV name (`"DICT_4X4_50"`, case-insensitive).
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL
            .into_iter()
            .find(|d| d.name.eq_ignore_ascii_case(name.trim()))
    }

    /// The OpenCV name.
    pub fn name(&self) -> &'static str {
        self.name
    }

    /// Number of marker codes [-].
    pub fn size(&self) -> usize {
        self.size
    }
}

/// Where the board lies in the workspace frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoardPlacement {
    /// The board origin in the workspace frame [m].
    pub origin_m: Vec3,
    /// Rotation of the board about the workspace z axis [rad].
    pub yaw_rad: f64,
}

impl BoardPlacement {
    /// The board frame is the workspace frame.
    pub fn identity() -> Self {
        Self {
            origin_m: Vec3::zeros(),
            yaw_rad: 0.0,
        }
    }

    /// The rigid transform workspace ← board.
    pub fn world_from_board(&self) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::from(self.origin_m),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), self.yaw_rad),
        )
    }
}

/// A ChArUco board: geometry, dictionary, the minimum corner count and its placement.
#[derive(Debug, Clone, PartialEq)]
pub struct BoardSpec {
    squares_x: u32,
    squares_y: u32,
    square_m: f64,
    marker_m: f64,
    dictionary: ArucoDictionary,
    min_corners: usize,
    placement: BoardPlacement,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBoard {
    squares_x: u32,
    squares_y: u32,
    square_m: f64,
    marker_m: f64,
    dictionary: String,
    #[serde(default = "default_min_corners")]
    min_corners: usize,
    placement: Option<RawPlacement>,
}

fn default_min_corners() -> usize {
    DEFAULT_MIN_CORNERS
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPlacement {
    #[serde(default)]
    origin_m: [f64; 3],
    #[serde(default)]
    yaw_deg: f64,
}

impl Default for BoardSpec {
    /// 5 × 7 squares of 40 mm, 30 mm `DICT_4X4_50` markers, 6 corners minimum, identity
    /// placement (the contents of `config/board.toml`).
    fn default() -> Self {
        Self {
            squares_x: 5,
            squares_y: 7,
            square_m: 0.040,
            marker_m: 0.030,
            dictionary: ArucoDictionary::ALL[0],
            min_corners: DEFAULT_MIN_CORNERS,
            placement: BoardPlacement::identity(),
        }
    }
}

impl BoardSpec {
    /// A validated board: `squares_x`, `squares_y` ≥ 3 with `squares_y` odd (boards with an
    /// even row count are laid out differently by OpenCV before 4.6, its "legacy pattern"),
    /// 0 < `marker_m` < `square_m` [m], the dictionary holding all ⌊x·y/2⌋ markers, and
    /// 4 ≤ `min_corners` ≤ (x − 1)(y − 1).
    pub fn new(
        squares_x: u32,
        squares_y: u32,
        square_m: f64,
        marker_m: f64,
        dictionary: ArucoDictionary,
        min_corners: usize,
        placement: BoardPlacement,
    ) -> Result<Self> {
        if !(3..=64).contains(&squares_x) || !(3..=64).contains(&squares_y) {
            return Err(AssessError::invalid(
                "squares_x/squares_y",
                format!("each must be 3..=64 (got {squares_x} x {squares_y})"),
            ));
        }
        if squares_y.is_multiple_of(2) {
            return Err(AssessError::invalid(
                "squares_y",
                format!(
                    "must be odd (got {squares_y}): boards with an even row count differ between \
                     OpenCV versions (the legacy pattern before 4.6)"
                ),
            ));
        }
        if !(square_m.is_finite() && square_m > 0.0 && square_m < 1.0) {
            return Err(AssessError::invalid(
                "square_m",
                format!("must be in (0, 1) m (got {square_m})"),
            ));
        }
        if !(marker_m.is_finite() && marker_m > 0.0 && marker_m < square_m) {
            return Err(AssessError::invalid(
                "marker_m",
                format!("must be > 0 and < square_m = {square_m} m (got {marker_m})"),
            ));
        }
        let markers = (squares_x * squares_y / 2) as usize;
        if markers > dictionary.size() {
            return Err(AssessError::invalid(
                "dictionary",
                format!(
                    "{} holds {} markers; a {squares_x} x {squares_y} board needs {markers}",
                    dictionary.name(),
                    dictionary.size()
                ),
            ));
        }
        let corners = ((squares_x - 1) * (squares_y - 1)) as usize;
        if !(4..=corners).contains(&min_corners) {
            return Err(AssessError::invalid(
                "min_corners",
                format!("must be 4..={corners} for this board (got {min_corners})"),
            ));
        }
        if !(placement.origin_m.iter().all(|v| v.is_finite()) && placement.yaw_rad.is_finite()) {
            return Err(AssessError::invalid("placement", "values must be finite"));
        }
        Ok(Self {
            squares_x,
            squares_y,
            square_m,
            marker_m,
            dictionary,
            min_corners,
            placement,
        })
    }

    /// Loads a board TOML file (format: `config/board.toml`). Errors name the file and key.
    pub fn from_toml_file(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let text = crate::error::read_text(path)?;
        Self::parse(&text, path).map_err(|e| in_file(e, path))
    }

    /// Parses a board TOML document.
    pub fn from_toml_str(text: &str) -> Result<Self> {
        Self::parse(text, Path::new("<string>"))
    }

    fn parse(text: &str, origin: &Path) -> Result<Self> {
        let raw: RawBoard = crate::error::parse_toml(text, origin)?;
        let dictionary = ArucoDictionary::from_name(&raw.dictionary).ok_or_else(|| {
            AssessError::invalid(
                "dictionary",
                format!(
                    "unknown ArUco dictionary `{}` (use DICT_<4..7>X<4..7>_<50|100|250|1000>)",
                    raw.dictionary
                ),
            )
        })?;
        let placement = raw
            .placement
            .map_or(BoardPlacement::identity(), |p| BoardPlacement {
                origin_m: Vec3::from(p.origin_m),
                yaw_rad: p.yaw_deg.to_radians(),
            });
        Self::new(
            raw.squares_x,
            raw.squares_y,
            raw.square_m,
            raw.marker_m,
            dictionary,
            raw.min_corners,
            placement,
        )
    }

    /// Squares along x [-].
    pub fn squares_x(&self) -> u32 {
        self.squares_x
    }

    /// Squares along y [-].
    pub fn squares_y(&self) -> u32 {
        self.squares_y
    }

    /// Square side [m].
    pub fn square_m(&self) -> f64 {
        self.square_m
    }

    /// Marker side [m].
    pub fn marker_m(&self) -> f64 {
        self.marker_m
    }

    /// The marker dictionary.
    pub fn dictionary(&self) -> ArucoDictionary {
        self.dictionary
    }

    /// The fewest corners a pose is computed from [-].
    pub fn min_corners(&self) -> usize {
        self.min_corners
    }

    /// Where the board lies in the workspace frame.
    pub fn placement(&self) -> BoardPlacement {
        self.placement
    }

    /// The same board at another placement.
    pub fn with_placement(mut self, placement: BoardPlacement) -> Self {
        self.placement = placement;
        self
    }

    /// Board size without margin, x by y [m].
    pub fn size_m(&self) -> (f64, f64) {
        (
            f64::from(self.squares_x) * self.square_m,
            f64::from(self.squares_y) * self.square_m,
        )
    }

    /// The interior chessboard corners in the board frame [m], indexed by ChArUco corner id.
    ///
    /// OpenCV 4.6 numbers them row by row from the top-left of the printed board, x fastest,
    /// in its own board frame (origin top-left, y down the page, z into it); this is the same
    /// plane turned 180° about x: (x, y, z) = (x_cv, height − y_cv, −z_cv).
    pub fn corner_points(&self) -> Vec<Vec3> {
        let (_, height) = self.size_m();
        let mut out = Vec::with_capacity(((self.squares_x - 1) * (self.squares_y - 1)) as usize);
        for row in 1..self.squares_y {
            for col in 1..self.squares_x {
                out.push(Vec3::new(
                    f64::from(col) * self.square_m,
                    height - f64::from(row) * self.square_m,
                    0.0,
                ));
            }
        }
        out
    }

    fn cv_board(&self) -> Result<(Ptr<aruco::Dictionary>, Ptr<aruco::CharucoBoard>)> {
        let err = cv_err("ChArUco board");
        let dict = aruco::get_predefined_dictionary(self.dictionary.id).map_err(&err)?;
        let board = aruco::CharucoBoard::create(
            self.squares_x as i32,
            self.squares_y as i32,
            self.square_m as f32,
            self.marker_m as f32,
            &dict,
        )
        .map_err(&err)?;
        Ok((dict, board))
    }
}

impl fmt::Display for BoardSpec {
    /// "ChArUco 5x7, 40 mm squares, 30 mm markers, DICT_4X4_50".
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "ChArUco {}x{}, {} mm squares, {} mm markers, {}",
            self.squares_x,
            self.squares_y,
            self.square_m * 1000.0,
            self.marker_m * 1000.0,
            self.dictionary.name()
        )
    }
}

/// Appends the file to an invalid-value rule, so the message names both key and file.
fn in_file(e: AssessError, path: &Path) -> AssessError {
    match e {
        AssessError::InvalidValue { key, rule } => AssessError::InvalidValue {
            key,
            rule: format!("{rule} (in {})", path.display()),
        },
        other => other,
    }
}

// ---------------------------------------------------------------------------------------------
// Printing the board.

/// A rendered board, ready to print.
#[derive(Debug, Clone)]
pub struct BoardPrint {
    /// The image (black and white, as RGB).
    pub image: RgbImage,
    /// Print resolution: pixels per metre [px/m] (stored in the PNG's `pHYs` chunk).
    pub px_per_m: f64,
    /// Printed size including the margin, width by height [m].
    pub paper_m: (f64, f64),
    /// The white margin around the squares [m].
    pub margin_m: f64,
}

/// Renders the board at `dpi` [px/inch] with a white `margin_m` [m] around the squares. The
/// square side is rounded to whole pixels and the returned resolution is the exact one that
/// makes it `square_m` on paper. The origin corner and axes are labelled in the margin when the
/// margin is at least 8 mm.
pub fn render_board(board: &BoardSpec, dpi: f64, margin_m: f64) -> Result<BoardPrint> {
    if !(dpi.is_finite() && (10.0..=2400.0).contains(&dpi)) {
        return Err(AssessError::invalid(
            "dpi",
            format!("must be 10..=2400 (got {dpi})"),
        ));
    }
    if !(margin_m.is_finite() && (0.0..=0.2).contains(&margin_m)) {
        return Err(AssessError::invalid(
            "margin_m",
            format!("must be 0..=0.2 m (got {margin_m})"),
        ));
    }
    let square_px = (board.square_m * dpi / 0.0254).round().max(8.0);
    let px_per_m = square_px / board.square_m;
    let margin_px = (margin_m * px_per_m).round();
    let w = square_px * f64::from(board.squares_x) + 2.0 * margin_px;
    let h = square_px * f64::from(board.squares_y) + 2.0 * margin_px;
    let (_, mut cv) = board.cv_board()?;
    let mut gray = Mat::default();
    let err = cv_err("drawing the board");
    cv.draw(
        Size::new(w as i32, h as i32),
        &mut gray,
        margin_px as i32,
        1,
    )
    .map_err(&err)?;
    let mut image = rgb_from_mat(&gray, imgproc::COLOR_GRAY2RGB, "drawing the board")?;
    if margin_px / px_per_m >= 0.008 {
        // A tick at the origin and a one-line legend in the bottom margin, 3 mm tall.
        let x0 = margin_px;
        let y = h - margin_px * 0.3;
        draw::line(&mut image, (x0, h - margin_px), (x0, h - 1.0), [0, 0, 0], 2)?;
        let label = format!(
            "origin: this corner | x right, y up, z out of the page | {}x{}, {:.0}/{:.0} mm, {}",
            board.squares_x,
            board.squares_y,
            board.square_m * 1e3,
            board.marker_m * 1e3,
            board.dictionary.name()
        );
        // Hershey capitals advance about 0.9 of their height per character.
        let fit = (w - 2.0 * margin_px) / (label.len() as f64 * 0.9);
        draw::text_with_height(
            &mut image,
            &label,
            (x0 + 0.3 * margin_px, y),
            [255, 255, 255],
            (0.003 * px_per_m).min(fit),
        )?;
    }
    Ok(BoardPrint {
        image,
        px_per_m,
        paper_m: (w / px_per_m, h / px_per_m),
        margin_m: margin_px / px_per_m,
    })
}

/// Renders the board ([`render_board`]) and writes it as PNG with its print resolution in the
/// `pHYs` chunk, so printing at "100 %" / "actual size" gives `square_m` squares.
pub fn write_board_png(
    board: &BoardSpec,
    path: impl AsRef<Path>,
    dpi: f64,
    margin_m: f64,
) -> Result<BoardPrint> {
    let print = render_board(board, dpi, margin_m)?;
    let png = encode_png(&print.image)?;
    let png = with_phys_chunk(&png, print.px_per_m.round() as u32).ok_or_else(|| {
        AssessError::Vision {
            operation: "PNG encoding",
            message: "the encoder's output has no IHDR chunk".into(),
        }
    })?;
    let path = path.as_ref();
    std::fs::write(path, png).map_err(|source| AssessError::Write {
        path: path.to_path_buf(),
        source,
    })?;
    Ok(print)
}

/// The image as PNG bytes.
pub fn encode_png(image: &RgbImage) -> Result<Vec<u8>> {
    let err = cv_err("PNG encoding");
    let bgr = bgr_mat(image)?;
    let mut buf = Vector::<u8>::new();
    let ok = imgcodecs::imencode(".png", &bgr, &mut buf, &Vector::new()).map_err(&err)?;
    if !ok {
        return Err(AssessError::Vision {
            operation: "PNG encoding",
            message: "the encoder refused the image".into(),
        });
    }
    Ok(buf.to_vec())
}

/// Writes an image as PNG.
pub fn write_png(image: &RgbImage, path: impl AsRef<Path>) -> Result<()> {
    let png = encode_png(image)?;
    let path = path.as_ref();
    std::fs::write(path, png).map_err(|source| AssessError::Write {
        path: path.to_path_buf(),
        source,
    })
}

/// Inserts a `pHYs` chunk (pixels per metre, both axes) after the PNG's IHDR chunk; `None`
/// when the bytes do not start with a PNG signature and IHDR.
fn with_phys_chunk(png: &[u8], px_per_m: u32) -> Option<Vec<u8>> {
    const IHDR_END: usize = 8 + 4 + 4 + 13 + 4;
    if png.len() < IHDR_END || png.get(12..16)? != b"IHDR" {
        return None;
    }
    let mut chunk = Vec::with_capacity(21);
    chunk.extend_from_slice(&9u32.to_be_bytes());
    chunk.extend_from_slice(b"pHYs");
    chunk.extend_from_slice(&px_per_m.to_be_bytes());
    chunk.extend_from_slice(&px_per_m.to_be_bytes());
    chunk.push(1); // unit: metre
    let crc = crc32(chunk.get(4..)?);
    chunk.extend_from_slice(&crc.to_be_bytes());
    let mut out = Vec::with_capacity(png.len() + chunk.len());
    out.extend_from_slice(png.get(..IHDR_END)?);
    out.extend_from_slice(&chunk);
    out.extend_from_slice(png.get(IHDR_END..)?);
    Some(out)
}

/// CRC-32 (ISO-HDLC, as PNG uses), bitwise.
fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = 0xFFFF_FFFFu32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 == 1 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

// ---------------------------------------------------------------------------------------------
// Image conversions.

/// A BGR `Mat` (owned copy) of an RGB image.
pub(crate) fn bgr_mat(image: &RgbImage) -> Result<Mat> {
    let view = rgb_view(image)?;
    let mut bgr = Mat::default();
    imgproc::cvt_color_def(&view, &mut bgr, imgproc::COLOR_RGB2BGR)
        .map_err(cv_err("colour conversion"))?;
    Ok(bgr)
}

/// A borrowed CV_8UC3 view (R, G, B) of an image.
fn rgb_view(image: &RgbImage) -> Result<opencv::boxed_ref::BoxedRef<'_, Mat>> {
    if !image.is_well_formed() {
        return Err(AssessError::Vision {
            operation: "image",
            message: format!(
                "malformed image: {} x {} px with {} bytes",
                image.width,
                image.height,
                image.data.len()
            ),
        });
    }
    Mat::new_rows_cols_with_bytes::<Vec3b>(image.height as i32, image.width as i32, &image.data)
        .map_err(cv_err("image"))
}

/// An [`RgbImage`] from an 8-bit `Mat`, converted with `code` (`COLOR_BGR2RGB`,
/// `COLOR_GRAY2RGB`, ...).
pub(crate) fn rgb_from_mat(mat: &Mat, code: i32, operation: &'static str) -> Result<RgbImage> {
    let err = cv_err(operation);
    let mut rgb = Mat::default();
    imgproc::cvt_color_def(mat, &mut rgb, code).map_err(&err)?;
    let rgb = if rgb.is_continuous() {
        rgb
    } else {
        rgb.try_clone().map_err(&err)?
    };
    let (w, h) = (rgb.cols(), rgb.rows());
    if w <= 0 || h <= 0 || rgb.typ() != core::CV_8UC3 {
        return Err(AssessError::Vision {
            operation,
            message: format!(
                "expected a non-empty 8-bit image (got {w} x {h}, type {})",
                rgb.typ()
            ),
        });
    }
    Ok(RgbImage {
        width: w as u32,
        height: h as u32,
        data: rgb.data_bytes().map_err(&err)?.to_vec(),
    })
}

// ---------------------------------------------------------------------------------------------
// Calibration.

/// ChArUco corners found in an image.
#[derive(Debug, Clone, PartialEq)]
pub struct BoardDetection {
    /// ArUco markers detected [-].
    pub markers: usize,
    /// Interpolated, sub-pixel chessboard corners: (corner id, u [px], v [px]).
    pub corners: Vec<(usize, f64, f64)>,
}

/// The result of [`calibrate`].
#[derive(Debug, Clone)]
pub struct BoardCalibration {
    /// Workspace ← camera.
    pub extrinsics: Extrinsics,
    /// Board ← camera (the camera pose relative to the board, before the placement).
    pub board_from_camera: Isometry3<f64>,
    /// RMS distance between the detected corners and the corners reprojected with the pose [px].
    pub reprojection_rms_px: f64,
    /// What was detected; `corners.len()` corners were used.
    pub detection: BoardDetection,
}

fn camera_matrix(k: &Intrinsics) -> Result<Mat> {
    Mat::from_slice_2d(&[[k.fx, 0.0, k.cx], [0.0, k.fy, k.cy], [0.0, 0.0, 1.0]])
        .map_err(cv_err("camera matrix"))
}

fn check_intrinsics(image: &RgbImage, k: &Intrinsics) -> Result<()> {
    if ![k.fx, k.fy, k.cx, k.cy].iter().all(|v| v.is_finite()) || k.fx <= 0.0 || k.fy <= 0.0 {
        return Err(AssessError::invalid(
            "intrinsics",
            format!(
                "fx, fy must be > 0 and all values finite (got fx {}, fy {}, cx {}, cy {})",
                k.fx, k.fy, k.cx, k.cy
            ),
        ));
    }
    if (k.width, k.height) != (image.width, image.height) {
        return Err(AssessError::invalid(
            "intrinsics",
            format!(
                "they are for {} x {} px but the image is {} x {} px",
                k.width, k.height, image.width, image.height
            ),
        ));
    }
    Ok(())
}

/// Detects the board's markers and interpolates its chessboard corners (sub-pixel). Fails when
/// no marker of the board's dictionary is found; returns whatever corners were found otherwise.
pub fn detect_board(
    board: &BoardSpec,
    image: &RgbImage,
    intrinsics: &Intrinsics,
) -> Result<BoardDetection> {
    check_intrinsics(image, intrinsics)?;
    let view = rgb_view(image)?;
    let mut gray = Mat::default();
    imgproc::cvt_color_def(&view, &mut gray, imgproc::COLOR_RGB2GRAY)
        .map_err(cv_err("colour conversion"))?;
    let (dict, cv_board) = board.cv_board()?;
    let err = cv_err("ArUco detection");
    let params = aruco::DetectorParameters::create().map_err(&err)?;
    let mut marker_corners = Vector::<Vector<Point2f>>::new();
    let mut marker_ids = Vector::<i32>::new();
    let mut rejected = Vector::<Vector<Point2f>>::new();
    aruco::detect_markers(
        &gray,
        &dict,
        &mut marker_corners,
        &mut marker_ids,
        &params,
        &mut rejected,
    )
    .map_err(&err)?;
    if marker_ids.is_empty() {
        return Err(AssessError::Vision {
            operation: "ArUco detection",
            message: format!(
                "no {} marker found in the {} x {} px image ({} candidate squares rejected); \
                 is the board ({board}) in view, lit, in focus and not mirrored?",
                board.dictionary.name(),
                image.width,
                image.height,
                rejected.len()
            ),
        });
    }
    let k = camera_matrix(intrinsics)?;
    let dist = Vector::<f64>::from_slice(&[0.0; 5]);
    let mut ch_corners = Vector::<Point2f>::new();
    let mut ch_ids = Vector::<i32>::new();
    aruco::interpolate_corners_charuco(
        &marker_corners,
        &marker_ids,
        &gray,
        &cv_board,
        &mut ch_corners,
        &mut ch_ids,
        &k,
        &dist,
        2,
    )
    .map_err(cv_err("ChArUco corner interpolation"))?;
    let n_ids = (board.squares_x as usize - 1) * (board.squares_y as usize - 1);
    let corners = ch_ids
        .iter()
        .zip(ch_corners.iter())
        .filter_map(|(id, p)| {
            let id = usize::try_from(id).ok().filter(|&id| id < n_ids)?;
            Some((id, f64::from(p.x), f64::from(p.y)))
        })
        .collect();
    Ok(BoardDetection {
        markers: marker_ids.len(),
        corners,
    })
}

/// Calibrates the camera against the board in `image` (see the module docs). `intrinsics` are
/// the colour camera's and must match the image size.
pub fn calibrate(
    board: &BoardSpec,
    image: &RgbImage,
    intrinsics: &Intrinsics,
) -> Result<BoardCalibration> {
    let detection = detect_board(board, image, intrinsics)?;
    if detection.corners.len() < board.min_corners {
        return Err(AssessError::Vision {
            operation: "ChArUco corner interpolation",
            message: format!(
                "only {} board corners found ({} markers), at least {} needed; \
                 show more of the board, closer or better lit",
                detection.corners.len(),
                detection.markers,
                board.min_corners
            ),
        });
    }
    let points = board.corner_points();
    let mut object = Vector::<Point3f>::new();
    let mut pixels = Vector::<Point2f>::new();
    for &(id, u, v) in &detection.corners {
        if let Some(p) = points.get(id) {
            object.push(Point3f::new(p.x as f32, p.y as f32, 0.0));
            pixels.push(Point2f::new(u as f32, v as f32));
        }
    }
    let k = camera_matrix(intrinsics)?;
    let dist = Vector::<f64>::from_slice(&[0.0; 5]);
    let mut rvec = Mat::default();
    let mut tvec = Mat::default();
    let err = cv_err("solvePnP");
    let ok = calib3d::solve_pnp(
        &object,
        &pixels,
        &k,
        &dist,
        &mut rvec,
        &mut tvec,
        false,
        calib3d::SOLVEPNP_IPPE,
    )
    .map_err(&err)?;
    if !ok {
        return Err(AssessError::Vision {
            operation: "solvePnP",
            message: format!(
                "no pose from {} corners (are they collinear?)",
                object.len()
            ),
        });
    }
    calib3d::solve_pnp_refine_lm_def(&object, &pixels, &k, &dist, &mut rvec, &mut tvec)
        .map_err(&err)?;
    let r = mat3(&rvec).map_err(&err)?;
    let t = mat3(&tvec).map_err(&err)?;
    let camera_from_board = Isometry3::from_parts(
        Translation3::from(t),
        UnitQuaternion::from_rotation_matrix(&Rotation3::new(r)),
    );
    if !camera_from_board
        .translation
        .vector
        .iter()
        .chain(camera_from_board.rotation.coords.iter())
        .all(|v| v.is_finite())
    {
        return Err(AssessError::Vision {
            operation: "solvePnP",
            message: "the pose is not finite".into(),
        });
    }
    let board_from_camera = camera_from_board.inverse();
    if board_from_camera.translation.z <= 0.0 {
        return Err(AssessError::Vision {
            operation: "solvePnP",
            message: format!(
                "the pose puts the camera {:.3} m behind the board; is the image mirrored?",
                -board_from_camera.translation.z
            ),
        });
    }
    let mut sq = 0.0;
    for &(id, u, v) in &detection.corners {
        let Some(p) = points.get(id) else { continue };
        let c = camera_from_board * Point3::from(*p);
        let (pu, pv) = intrinsics.project(&c).unwrap_or((f64::INFINITY, 0.0));
        sq += (pu - u).powi(2) + (pv - v).powi(2);
    }
    let reprojection_rms_px = (sq / detection.corners.len() as f64).sqrt();
    let world_from_camera = board.placement.world_from_board() * board_from_camera;
    Ok(BoardCalibration {
        extrinsics: Extrinsics { world_from_camera },
        board_from_camera,
        reprojection_rms_px,
        detection,
    })
}

/// The three values of a 3 × 1 (or 1 × 3) CV_64F `Mat`.
fn mat3(m: &Mat) -> opencv::Result<Vector3<f64>> {
    let v = m.data_typed::<f64>()?;
    match v {
        [a, b, c] => Ok(Vector3::new(*a, *b, *c)),
        _ => Err(opencv::Error::new(
            core::StsBadSize,
            format!("expected 3 values, got {}", v.len()),
        )),
    }
}

// ---------------------------------------------------------------------------------------------
// Check image.

/// Draws, on a copy of the colour image, everything needed to check a calibration by eye: the
/// workspace areas' boxes and names (if given), the workspace axes at the origin (0.2 m), the
/// board outline and axes (0.1 m), the detected corners (green dots) and a text summary.
pub fn check_image(
    image: &RgbImage,
    intrinsics: &Intrinsics,
    extrinsics: &Extrinsics,
    board: &BoardSpec,
    workspace: Option<&Workspace>,
    calibration: Option<&BoardCalibration>,
) -> Result<RgbImage> {
    let mut out = image.clone();
    let proj = Projector::new(*intrinsics, extrinsics);
    if let Some(ws) = workspace {
        draw::areas(&mut out, &proj, ws, None)?;
    }
    let world_from_board = board.placement.world_from_board();
    let (bw, bh) = board.size_m();
    let outline = [
        Vec3::zeros(),
        Vec3::new(bw, 0.0, 0.0),
        Vec3::new(bw, bh, 0.0),
        Vec3::new(0.0, bh, 0.0),
    ]
    .map(|p| (world_from_board * Point3::from(p)).coords);
    for i in 0..4 {
        let (a, b) = (outline[i], outline[(i + 1) % 4]);
        draw::segment_3d(&mut out, &proj, &a, &b, draw::WHITE, 2)?;
    }
    draw::axes(&mut out, &proj, &Isometry3::identity(), 0.2)?;
    draw::axes(&mut out, &proj, &world_from_board, 0.1)?;
    let mut lines = vec![format!("board: {board}")];
    if let Some(c) = calibration {
        for &(_, u, v) in &c.detection.corners {
            draw::dot(&mut out, (u, v), 3, draw::GREEN)?;
        }
        lines.push(format!(
            "{} corners, {} markers, reprojection RMS {:.2} px",
            c.detection.corners.len(),
            c.detection.markers,
            c.reprojection_rms_px
        ));
    }
    let cam = extrinsics.world_from_camera.translation.vector;
    lines.push(format!(
        "camera at ({:.3}, {:.3}, {:.3}) m in the workspace frame",
        cam.x, cam.y, cam.z
    ));
    lines.push("axes: x red, y green, z blue (workspace 0.2 m, board 0.1 m)".into());
    draw::text_lines(&mut out, &lines, draw::WHITE)?;
    Ok(out)
}

// ---------------------------------------------------------------------------------------------
// Extrinsics file.

/// How an extrinsics calibration was obtained (the `[calibration]` table of the file).
#[derive(Debug, Clone, PartialEq)]
pub struct CalibrationInfo {
    /// The board, as [`BoardSpec`]'s `Display` gives it.
    pub board: String,
    /// Where the image came from ("image board.jpg", "webcam 0").
    pub source: String,
    /// When, as the caller stamped it (ISO 8601 UTC).
    pub date: String,
    /// Reprojection RMS [px].
    pub reprojection_rms_px: f64,
    /// Corners used [-].
    pub corners: usize,
    /// The colour intrinsics used (their width and height are the image size [px]).
    pub intrinsics: Intrinsics,
}

/// The contents of an extrinsics file: the transform and, optionally, its provenance.
#[derive(Debug, Clone, PartialEq)]
pub struct ExtrinsicsFile {
    /// Workspace ← camera.
    pub extrinsics: Extrinsics,
    /// How it was obtained.
    pub info: Option<CalibrationInfo>,
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawExtrinsicsFile {
    extrinsics: RawExtrinsics,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    calibration: Option<RawInfo>,
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawExtrinsics {
    rotation_xyzw: [f64; 4],
    translation_m: [f64; 3],
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawInfo {
    board: String,
    #[serde(default)]
    source: String,
    date: String,
    reprojection_rms_px: f64,
    corners: usize,
    image_size_px: [u32; 2],
    intrinsics: RawIntrinsics,
}

/// Pinhole intrinsics as TOML (`fx_px`, `fy_px`, `cx_px`, `cy_px`); shared with the depth
/// sequences' `depth.toml`.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawIntrinsics {
    pub(crate) fx_px: f64,
    pub(crate) fy_px: f64,
    pub(crate) cx_px: f64,
    pub(crate) cy_px: f64,
}

impl RawIntrinsics {
    /// Validated intrinsics for an image of `width` × `height` [px]; `key` names the table.
    pub(crate) fn validate(&self, key: &str, width: u32, height: u32) -> Result<Intrinsics> {
        for (name, v) in [
            ("fx_px", self.fx_px),
            ("fy_px", self.fy_px),
            ("cx_px", self.cx_px),
            ("cy_px", self.cy_px),
        ] {
            if !v.is_finite() {
                return Err(AssessError::invalid(
                    format!("{key}.{name}"),
                    format!("must be finite (got {v})"),
                ));
            }
        }
        if self.fx_px <= 0.0 || self.fy_px <= 0.0 {
            return Err(AssessError::invalid(
                format!("{key}.fx_px/fy_px"),
                format!("must be > 0 (got {} and {})", self.fx_px, self.fy_px),
            ));
        }
        if width == 0 || height == 0 {
            return Err(AssessError::invalid(
                "image_size_px",
                format!("must be > 0 (got {width} x {height})"),
            ));
        }
        Ok(Intrinsics {
            width,
            height,
            fx: self.fx_px,
            fy: self.fy_px,
            cx: self.cx_px,
            cy: self.cy_px,
        })
    }

    pub(crate) fn from_intrinsics(k: &Intrinsics) -> Self {
        Self {
            fx_px: k.fx,
            fy_px: k.fy,
            cx_px: k.cx,
            cy_px: k.cy,
        }
    }
}

const FILE_HEADER: &str = "\
# Camera extrinsics for hrc-adapt (assess::vision::calib).
# [extrinsics] is world_from_camera: it maps camera-frame points [m] (x right, y down, z along
# the optical axis) to the workspace frame [m] (z up). rotation_xyzw is a unit quaternion
# (x, y, z, w); translation_m is the camera's optical centre in the workspace frame.
";

impl ExtrinsicsFile {
    /// Parses and validates an extrinsics TOML document (see the module docs).
    pub fn from_toml_str(text: &str) -> Result<Self> {
        Self::parse(text, Path::new("<string>"))
    }

    /// Loads an extrinsics file. Errors name the file and the key.
    pub fn load(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let text = crate::error::read_text(path)?;
        Self::parse(&text, path).map_err(|e| in_file(e, path))
    }

    fn parse(text: &str, origin: &Path) -> Result<Self> {
        let raw: RawExtrinsicsFile = crate::error::parse_toml(text, origin)?;
        let [x, y, z, w] = raw.extrinsics.rotation_xyzw;
        if ![x, y, z, w].iter().all(|v| v.is_finite()) {
            return Err(AssessError::invalid(
                "extrinsics.rotation_xyzw",
                format!("must be finite (got {:?})", raw.extrinsics.rotation_xyzw),
            ));
        }
        let q = Quaternion::new(w, x, y, z);
        let norm = q.norm();
        if (norm - 1.0).abs() > QUATERNION_NORM_TOLERANCE {
            return Err(AssessError::invalid(
                "extrinsics.rotation_xyzw",
                format!(
                    "must be a unit quaternion (x, y, z, w): its norm is {norm:.6}, \
                     more than {QUATERNION_NORM_TOLERANCE} from 1"
                ),
            ));
        }
        let t = raw.extrinsics.translation_m;
        if !t.iter().all(|v| v.is_finite()) {
            return Err(AssessError::invalid(
                "extrinsics.translation_m",
                format!("must be finite (got {t:?})"),
            ));
        }
        let extrinsics = Extrinsics {
            world_from_camera: Isometry3::from_parts(
                Translation3::new(t[0], t[1], t[2]),
                UnitQuaternion::from_quaternion(q),
            ),
        };
        let info = match raw.calibration {
            None => None,
            Some(c) => {
                if !(c.reprojection_rms_px.is_finite() && c.reprojection_rms_px >= 0.0) {
                    return Err(AssessError::invalid(
                        "calibration.reprojection_rms_px",
                        format!("must be finite and >= 0 (got {})", c.reprojection_rms_px),
                    ));
                }
                let [w, h] = c.image_size_px;
                Some(CalibrationInfo {
                    board: c.board,
                    source: c.source,
                    date: c.date,
                    reprojection_rms_px: c.reprojection_rms_px,
                    corners: c.corners,
                    intrinsics: c.intrinsics.validate("calibration.intrinsics", w, h)?,
                })
            }
        };
        Ok(Self { extrinsics, info })
    }

    /// The file as TOML text, with a header comment explaining the convention.
    pub fn to_toml_string(&self) -> Result<String> {
        let iso = &self.extrinsics.world_from_camera;
        let q = iso.rotation.coords; // (i, j, k, w)
        let t = iso.translation.vector;
        let raw = RawExtrinsicsFile {
            extrinsics: RawExtrinsics {
                rotation_xyzw: [q.x, q.y, q.z, q.w],
                translation_m: [t.x, t.y, t.z],
            },
            calibration: self.info.as_ref().map(|c| RawInfo {
                board: c.board.clone(),
                source: c.source.clone(),
                date: c.date.clone(),
                reprojection_rms_px: c.reprojection_rms_px,
                corners: c.corners,
                image_size_px: [c.intrinsics.width, c.intrinsics.height],
                intrinsics: RawIntrinsics::from_intrinsics(&c.intrinsics),
            }),
        };
        let body = toml::to_string(&raw).map_err(|e| AssessError::Serialize {
            what: "extrinsics",
            message: e.to_string(),
        })?;
        Ok(format!("{FILE_HEADER}\n{body}"))
    }

    /// Writes the file.
    pub fn save(&self, path: impl AsRef<Path>) -> Result<()> {
        let text = self.to_toml_string()?;
        let path = path.as_ref();
        std::fs::write(path, text).map_err(|source| AssessError::Write {
            path: PathBuf::from(path),
            source,
        })
    }
}

impl Extrinsics {
    /// Loads the transform of an extrinsics file ([`ExtrinsicsFile::load`]).
    pub fn load(path: impl AsRef<Path>) -> Result<Self> {
        Ok(ExtrinsicsFile::load(path)?.extrinsics)
    }

    /// Writes the transform alone as an extrinsics file (no `[calibration]` table).
    pub fn save(&self, path: impl AsRef<Path>) -> Result<()> {
        ExtrinsicsFile {
            extrinsics: *self,
            info: None,
        }
        .save(path)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc32_matches_the_standard_check_value() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
    }

    #[test]
    fn phys_chunk_is_inserted_after_ihdr() {
        let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
        png.extend_from_slice(&13u32.to_be_bytes());
        png.extend_from_slice(b"IHDR");
        png.extend_from_slice(&[0; 13 + 4]);
        png.extend_from_slice(b"rest");
        let out = with_phys_chunk(&png, 11_811).expect("png");
        assert_eq!(&out[33 + 4..33 + 8], b"pHYs");
        assert_eq!(&out[33 + 8..33 + 12], &11_811u32.to_be_bytes());
        assert_eq!(out[33 + 16], 1);
        assert_eq!(&out[out.len() - 4..], b"rest");
        assert_eq!(out.len(), png.len() + 21);
        assert!(with_phys_chunk(b"not a png", 1).is_none());
    }

    #[test]
    fn corner_points_follow_opencv_ids() {
        use opencv::aruco::CharucoBoardTraitConst as _;
        let b = BoardSpec::default();
        let p = b.corner_points();
        assert_eq!(p.len(), 4 * 6);
        assert!((p[0] - Vec3::new(0.04, 0.24, 0.0)).norm() < 1e-12);
        assert!((p[3] - Vec3::new(0.16, 0.24, 0.0)).norm() < 1e-12);
        assert!((p[4] - Vec3::new(0.04, 0.20, 0.0)).norm() < 1e-12);
        let (_, cv) = b.cv_board().expect("board");
        let theirs = cv.chessboard_corners();
        assert_eq!(theirs.len(), p.len());
        for (ours, c) in p.iter().zip(theirs.iter()) {
            let mapped = Vec3::new(f64::from(c.x), 0.28 - f64::from(c.y), -f64::from(c.z));
            assert!((ours - mapped).norm() < 1e-6, "{ours} vs {mapped}");
        }
    }
}
