//! What perception writes: landmarks as CSV ([`LandmarkCsv`]), the privacy-preserving record
//! every camera run keeps, and camera images ([`ImageSink`]), written only where a user asked
//! for them.

use std::fmt::Write as _;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use super::source::capture::VideoSink;
use super::{Landmarks, RgbImage, calib};
use crate::{AssessError, Result};

/// The header of [`LandmarkCsv`] files.
pub const LANDMARK_HEADER: &str = "frame,t,set,index,x_px,y_px,score";

/// `landmarks.csv`: one row per landmark, `frame,t,set,index,x_px,y_px,score`.
///
/// - `frame`: the source's frame number; `t`: camera time [s];
/// - `set`: `pose` (33), `face` (468), `hand0` / `hand1` (21 each, in the pipeline's order;
///   which hand is left or right is in the cues);
/// - `x_px`, `y_px`: image position [px] (MediaPipe's continuous coordinates: pixel (u, v)
///   spans [u, u + 1));
/// - `score` [-]: a pose landmark's visibility; for face and hands, the set's presence score.
#[derive(Debug)]
pub struct LandmarkCsv {
    path: PathBuf,
    out: BufWriter<File>,
    line: String,
}

impl LandmarkCsv {
    /// Creates the file and writes the header.
    pub fn create(path: &Path) -> Result<Self> {
        let write_err = |source| AssessError::Write {
            path: path.to_path_buf(),
            source,
        };
        let mut out = BufWriter::new(File::create(path).map_err(write_err)?);
        writeln!(out, "{LANDMARK_HEADER}").map_err(write_err)?;
        Ok(Self {
            path: path.to_path_buf(),
            out,
            line: String::with_capacity(64),
        })
    }

    /// Appends one frame's landmarks.
    pub fn write(&mut self, frame: u64, t: f64, lm: &Landmarks) -> Result<()> {
        if let Some(pose) = &lm.pose {
            for (i, p) in pose.points.iter().enumerate() {
                self.row(frame, t, "pose", i, p.x, p.y, p.visibility)?;
            }
        }
        if let Some(face) = &lm.face {
            for (i, p) in face.points.iter().enumerate() {
                self.row(frame, t, "face", i, p.x, p.y, face.score)?;
            }
        }
        for (h, hand) in lm.hands.iter().enumerate() {
            let set = if h == 0 { "hand0" } else { "hand1" };
            for (i, p) in hand.points.iter().enumerate() {
                self.row(frame, t, set, i, p.x, p.y, hand.score)?;
            }
        }
        Ok(())
    }

    #[allow(clippy::too_many_arguments)]
    fn row(
        &mut self,
        frame: u64,
        t: f64,
        set: &str,
        index: usize,
        x: f64,
        y: f64,
        score: f64,
    ) -> Result<()> {
        self.line.clear();
        let _ = writeln!(
            self.line,
            "{frame},{t:.6},{set},{index},{x:.2},{y:.2},{score:.4}"
        );
        self.out
            .write_all(self.line.as_bytes())
            .map_err(|source| self.write_error(source))
    }

    fn write_error(&self, source: std::io::Error) -> AssessError {
        AssessError::Write {
            path: self.path.clone(),
            source,
        }
    }

    /// Flushes the file.
    pub fn finish(mut self) -> Result<()> {
        self.out.flush().map_err(|source| self.write_error(source))
    }
}

/// Where camera images go when the user asked for them: an MJPG `.avi` video ([`VideoSink`])
/// or, for a path without extension, a folder of numbered PNGs (`000000.png`, ...). A video
/// needs every frame at one size; a PNG folder does not.
#[derive(Debug)]
pub enum ImageSink {
    /// A PNG folder.
    Pngs {
        /// The folder.
        dir: PathBuf,
        /// Frames written.
        n: u64,
    },
    /// An MJPG `.avi` file.
    Avi(VideoSink),
}

impl ImageSink {
    /// Creates the sink for `path`: `.avi` → video at `fps` [1/s] (the source's nominal rate),
    /// no extension → PNG folder (created; it must not exist or be empty). Other extensions, an
    /// existing video and a non-empty folder are [`AssessError::Output`]: nothing is
    /// overwritten.
    pub fn create(path: &Path, fps: f64) -> Result<Self> {
        let refuse = |message: &str| AssessError::Output {
            path: path.to_path_buf(),
            message: message.to_owned(),
        };
        match path.extension().and_then(|e| e.to_str()) {
            None => {
                let listed = |source| AssessError::Io {
                    path: path.to_path_buf(),
                    source,
                };
                if path.exists() && std::fs::read_dir(path).map_err(listed)?.next().is_some() {
                    return Err(refuse("the folder exists and is not empty"));
                }
                std::fs::create_dir_all(path).map_err(|source| AssessError::Write {
                    path: path.to_path_buf(),
                    source,
                })?;
                Ok(Self::Pngs {
                    dir: path.to_path_buf(),
                    n: 0,
                })
            }
            Some(e) if e.eq_ignore_ascii_case("avi") => {
                if path.exists() {
                    return Err(refuse("the file exists"));
                }
                Ok(Self::Avi(VideoSink::create(path, fps)?))
            }
            Some(_) => Err(refuse(
                "expected an .avi file, or a path without extension for a PNG folder",
            )),
        }
    }

    /// Appends one image.
    pub fn push(&mut self, image: &RgbImage) -> Result<()> {
        match self {
            Self::Pngs { dir, n } => {
                calib::write_png(image, dir.join(format!("{:06}.png", *n)))?;
                *n += 1;
                Ok(())
            }
            Self::Avi(v) => {
                if v.size().is_some_and(|s| s != (image.width, image.height)) {
                    return Err(AssessError::Output {
                        path: v.path().to_path_buf(),
                        message: format!(
                            "a video holds frames of one size, and this one is {} x {} px; for \
                             images of several sizes write a PNG folder (a path without \
                             extension)",
                            image.width, image.height
                        ),
                    });
                }
                v.write(image)
            }
        }
    }

    /// Closes the sink (a video's index is written here).
    pub fn finish(self) -> Result<()> {
        match self {
            Self::Pngs { .. } => Ok(()),
            Self::Avi(v) => v.finish(),
        }
    }
}
