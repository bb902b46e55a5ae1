//! ONNX Runtime sessions for MediaPipe's models (converted to ONNX by `scripts/models/convert`,
//! committed under `models/` with checksums).
//!
//! ONNX Runtime is loaded at run time (`ort`'s `load-dynamic`) from, in order: the path given
//! to [`init_runtime`], `ORT_DYLIB_PATH`, or the copy `scripts/setup` installs at
//! `.deps/onnxruntime/libonnxruntime.so` in the source tree. Each session gets one intra-op
//! thread: on the 2-core development machine two threads made a full frame 2.7× slower.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use ort::environment::Environment;
use ort::session::Session;
use ort::session::builder::GraphOptimizationLevel;
use ort::value::TensorRef;

use crate::{AssessError, Result};

/// The ONNX Runtime library `scripts/setup` installs, relative to the source tree.
pub const DEFAULT_RUNTIME: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../.deps/onnxruntime/libonnxruntime.so"
);

/// The committed models, relative to the source tree.
pub const DEFAULT_MODEL_DIR: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../models");

static RUNTIME: OnceLock<std::result::Result<(PathBuf, Environment), String>> = OnceLock::new();

/// The runtime library that [`init_runtime`] would load: `explicit`, else `ORT_DYLIB_PATH`,
/// else [`DEFAULT_RUNTIME`].
pub fn runtime_path(explicit: Option<&Path>) -> PathBuf {
    explicit
        .map(Path::to_path_buf)
        .or_else(|| std::env::var_os("ORT_DYLIB_PATH").map(PathBuf::from))
        .unwrap_or_else(|| PathBuf::from(DEFAULT_RUNTIME))
}

/// Loads ONNX Runtime once per process (later calls return the first outcome) and returns the
/// library's path.
pub fn init_runtime(explicit: Option<&Path>) -> Result<PathBuf> {
    environment(explicit).map(|(path, _)| path.clone())
}

fn environment(explicit: Option<&Path>) -> Result<&'static (PathBuf, Environment)> {
    let outcome = RUNTIME.get_or_init(|| {
        let path = runtime_path(explicit);
        if !path.exists() {
            return Err(format!(
                "{} not found; run scripts/setup (it installs ONNX Runtime 1.31.1 from PyPI) or \
                 set ORT_DYLIB_PATH",
                path.display()
            ));
        }
        let builder = ort::init_from(&path).map_err(|e| e.to_string())?;
        let env = builder
            .with_name("hrc-adapt")
            .build()
            .map_err(|e| e.to_string())?;
        Ok((path, env))
    });
    outcome.as_ref().map_err(|message| AssessError::Model {
        path: runtime_path(explicit),
        message: message.clone(),
    })
}

/// The model directory: `HRC_MODELS_DIR`, else [`DEFAULT_MODEL_DIR`].
pub fn model_dir() -> PathBuf {
    std::env::var_os("HRC_MODELS_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(DEFAULT_MODEL_DIR))
}

/// One model: an ONNX Runtime session with a single NHWC float input, whose outputs are
/// copied into reusable buffers in the session's output order.
#[derive(Debug)]
pub struct Model {
    path: PathBuf,
    session: Session,
    input_shape: [usize; 4],
    outputs: Vec<Vec<f32>>,
    output_names: Vec<String>,
}

impl Model {
    /// Loads `dir/<name>.onnx` with one intra-op thread. The runtime must be initialised
    /// ([`init_runtime`]); this does it with the defaults otherwise.
    pub fn load(dir: &Path, name: &str) -> Result<Self> {
        let (_, env) = environment(None)?;
        let path = dir.join(format!("{name}.onnx"));
        let err = |message: String| AssessError::Model {
            path: path.clone(),
            message,
        };
        if !path.exists() {
            return Err(err(
                "not found (the models are committed under models/; set HRC_MODELS_DIR to use \
                 another directory)"
                    .into(),
            ));
        }
        let session = Session::builder(env)
            .map_err(|e| err(e.to_string()))?
            .with_intra_threads(1)
            .map_err(|e| err(e.to_string()))?
            .with_optimization_level(GraphOptimizationLevel::Level3)
            .map_err(|e| err(e.to_string()))?
            .commit_from_file(&path)
            .map_err(|e| err(e.to_string()))?;
        let input = session
            .inputs()
            .first()
            .ok_or_else(|| err("the model has no input".into()))?;
        let dims: Vec<i64> = input
            .dtype()
            .tensor_shape()
            .map(|s| s.iter().copied().collect())
            .unwrap_or_default();
        let input_shape = match dims.as_slice() {
            [_, h, w, c] if *h > 0 && *w > 0 && *c == 3 => [1, *h as usize, *w as usize, 3],
            other => {
                return Err(err(format!(
                    "input `{}` has shape {other:?}; expected [1, H, W, 3] (NHWC RGB)",
                    input.name()
                )));
            }
        };
        let output_names: Vec<String> = session
            .outputs()
            .iter()
            .map(|o| o.name().to_string())
            .collect();
        let mut model = Self {
            path,
            outputs: vec![Vec::new(); output_names.len()],
            output_names,
            session,
            input_shape,
        };
        // One run on a zero tensor: sizes the output buffers (some converted models declare
        // dynamic output shapes) and warms the session up.
        let zeros = vec![0.0f32; input_shape.iter().product()];
        model.run(&zeros)?;
        Ok(model)
    }

    /// The number of values in each output, in order.
    pub fn output_sizes(&self) -> Vec<usize> {
        self.outputs.iter().map(Vec::len).collect()
    }

    /// Input (width, height) [px].
    pub fn input_size(&self) -> (u32, u32) {
        (self.input_shape[2] as u32, self.input_shape[1] as u32)
    }

    /// The output names, in order.
    pub fn output_names(&self) -> &[String] {
        &self.output_names
    }

    /// The model file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Runs the model on an NHWC tensor of `input_size` and keeps every output.
    pub fn run(&mut self, input: &[f32]) -> Result<()> {
        let path = &self.path;
        let err = |message: String| AssessError::Model {
            path: path.clone(),
            message,
        };
        let tensor = TensorRef::from_array_view((self.input_shape, input))
            .map_err(|e| err(e.to_string()))?;
        let outputs = self
            .session
            .run(ort::inputs![tensor])
            .map_err(|e| err(e.to_string()))?;
        for (i, buf) in self.outputs.iter_mut().enumerate() {
            let (_, data) = outputs[i]
                .try_extract_tensor::<f32>()
                .map_err(|e| err(e.to_string()))?;
            buf.clear();
            buf.extend_from_slice(data);
        }
        Ok(())
    }

    /// Output `i` of the last run (empty before the first run or for a bad index).
    pub fn output(&self, i: usize) -> &[f32] {
        self.outputs.get(i).map_or(&[], Vec::as_slice)
    }

    /// The index of the output named `name`.
    pub fn output_index(&self, name: &str) -> Result<usize> {
        self.output_names
            .iter()
            .position(|n| n == name)
            .ok_or_else(|| AssessError::Model {
                path: self.path.clone(),
                message: format!("no output named `{name}` (has {:?})", self.output_names),
            })
    }
}
