//! An image folder as a frame source ([`ImageFolderSource`]).
//!
//! The frames are the folder's image files (`.png`, `.jpg`, `.jpeg`, `.bmp`, `.tif`, `.tiff`,
//! `.webp`, any case; subfolders are ignored) in byte-wise file-name order, so name them with
//! zero-padded numbers. Frame `k` has the timestamp k / fps [s] with the options' nominal fps.
//! Optional depth: a [`DepthSequence`] folder whose PNG for a frame has the colour file's stem
//! (`000123.jpg` → `depth/000123.png`).
//!
//! # Intrinsics and image sizes
//!
//! The intrinsics, and with them the image size, are fixed when they are given in the options
//! or when there is a depth sequence (one camera's aligned recording, whose `depth.toml` may
//! give them; precedence as for video files, see [`super::capture`]): every image must then have
//! the first one's size. Otherwise each image gets [`Intrinsics::from_hfov`] for its own size, so
//! a folder may mix photos of different sizes and cameras (all assumed to have the options'
//! horizontal field of view).
//!
//! An unreadable or undecodable image, a missing depth PNG or, with fixed intrinsics, a frame
//! whose size differs from the first is an [`AssessError::Source`] naming the file; frames are
//! never skipped silently.

use std::path::{Path, PathBuf};

use opencv::imgcodecs;

use super::FrameSource;
use super::capture::{
    DEFAULT_FPS, DEFAULT_HFOV_DEG, DepthSequence, depth_note, frame_intrinsics, read_mat,
    resolve_intrinsics, rgb_from_decoded, source_err,
};
use crate::vision::frame::{CameraFrame, Intrinsics};
use crate::{AssessError, Result};

/// File extensions taken as images (compared case-insensitively).
pub const IMAGE_EXTENSIONS: [&str; 7] = ["png", "jpg", "jpeg", "bmp", "tif", "tiff", "webp"];

/// Options of an [`ImageFolderSource`].
#[derive(Debug, Clone)]
pub struct ImageFolderOptions {
    /// Nominal frame rate for timestamps [1/s].
    pub fps: f64,
    /// Colour intrinsics for every image (which must then all have their size); default: the
    /// depth sequence's, or from `hfov_deg` per image (module docs).
    pub intrinsics: Option<Intrinsics>,
    /// Horizontal field of view for the default intrinsics [deg].
    pub hfov_deg: f64,
    /// A depth sequence folder with PNGs named after the colour files' stems; it fixes the
    /// image size.
    pub depth: Option<PathBuf>,
}

impl Default for ImageFolderOptions {
    fn default() -> Self {
        Self {
            fps: DEFAULT_FPS,
            intrinsics: None,
            hfov_deg: DEFAULT_HFOV_DEG,
            depth: None,
        }
    }
}

/// Frames from the image files of a folder.
#[derive(Debug)]
pub struct ImageFolderSource {
    dir: PathBuf,
    files: Vec<PathBuf>,
    options: ImageFolderOptions,
    depth: Option<DepthSequence>,
    intrinsics: Option<Intrinsics>,
    next: usize,
}

/// Whether the path has one of [`IMAGE_EXTENSIONS`].
pub fn is_image_file(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| IMAGE_EXTENSIONS.iter().any(|x| x.eq_ignore_ascii_case(e)))
}

impl ImageFolderSource {
    /// Lists the folder's images (at least one) and opens the depth sequence, if any.
    pub fn open(dir: impl AsRef<Path>, options: ImageFolderOptions) -> Result<Self> {
        let dir = dir.as_ref().to_path_buf();
        let name = dir.display().to_string();
        if !(options.fps.is_finite() && options.fps > 0.1 && options.fps <= 1000.0) {
            return Err(AssessError::invalid(
                "fps",
                format!("must be in (0.1, 1000] (got {})", options.fps),
            ));
        }
        let entries = std::fs::read_dir(&dir).map_err(|source| AssessError::Io {
            path: dir.clone(),
            source,
        })?;
        let mut files = Vec::new();
        for entry in entries {
            let entry = entry.map_err(|source| AssessError::Io {
                path: dir.clone(),
                source,
            })?;
            let path = entry.path();
            if path.is_file() && is_image_file(&path) {
                files.push(path);
            }
        }
        if files.is_empty() {
            return Err(source_err(
                &name,
                format!(
                    "no image files ({}) in the folder",
                    IMAGE_EXTENSIONS.join(", ")
                ),
            ));
        }
        files.sort_by(|a, b| a.file_name().cmp(&b.file_name()));
        let depth = options
            .depth
            .as_ref()
            .map(DepthSequence::open)
            .transpose()?;
        Ok(Self {
            dir,
            files,
            options,
            depth,
            intrinsics: None,
            next: 0,
        })
    }

    /// The image files, in frame order.
    pub fn files(&self) -> &[PathBuf] {
        &self.files
    }

    /// The nominal frame rate of the timestamps [1/s].
    pub fn fps(&self) -> f64 {
        self.options.fps
    }

    /// Whether every image must have the same size (intrinsics fixed by the options or a depth
    /// sequence; module docs).
    pub fn fixed_size(&self) -> bool {
        self.options.intrinsics.is_some() || self.depth.is_some()
    }
}

impl FrameSource for ImageFolderSource {
    fn next_frame(&mut self) -> Result<Option<CameraFrame>> {
        let Some(path) = self.files.get(self.next) else {
            return Ok(None);
        };
        let name = path.display().to_string();
        let index = self.next as u64;
        // Advance first: a failing frame is reported once, and the caller may go on.
        self.next += 1;
        let color = crate::vision::RgbImage::read(path)?;
        let intrinsics = if self.fixed_size() {
            frame_intrinsics(
                &mut self.intrinsics,
                &self.dir.display().to_string(),
                &name,
                self.options.intrinsics,
                self.depth.as_ref(),
                self.options.hfov_deg,
                (color.width, color.height),
            )?
        } else {
            resolve_intrinsics(
                &name,
                None,
                None,
                self.options.hfov_deg,
                color.width,
                color.height,
            )?
        };
        let depth = match &self.depth {
            Some(seq) => {
                let stem = path
                    .file_stem()
                    .map(|s| s.to_os_string())
                    .unwrap_or_default();
                let mut file = stem;
                file.push(".png");
                Some(seq.read(&seq.dir().join(file), color.width, color.height)?)
            }
            None => None,
        };
        Ok(Some(CameraFrame {
            t: index as f64 / self.options.fps,
            index,
            color,
            depth,
            intrinsics,
        }))
    }

    fn describe(&self) -> String {
        format!(
            "image folder {} ({} images at {} fps{})",
            self.dir.display(),
            self.files.len(),
            self.options.fps,
            depth_note(self.depth.as_ref())
        )
    }

    fn has_depth(&self) -> bool {
        self.depth.is_some()
    }
}

/// Reads one image file (any format OpenCV decodes) as RGB. Errors name the file.
pub fn read_image(path: impl AsRef<Path>) -> Result<crate::vision::RgbImage> {
    let path = path.as_ref();
    let mat = read_mat(path, imgcodecs::IMREAD_COLOR, "image")?;
    rgb_from_decoded(&mat, &path.display().to_string())
}
