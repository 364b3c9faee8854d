//! The activity model on ONNX Runtime: loads the per-scan ConvLSTM step model of
//! `docs/model_contract.md`, checks it against the contract, and steps it for
//! [`lidar_har_core::classifier::StreamingClassifier`]; and the pose head that reads its
//! state ([`PoseHeadModel`]).
//!
//! ONNX Runtime is loaded at run time (`ort`'s `load-dynamic`): from `$ORT_DYLIB_PATH`, else
//! from `<repo>/.deps/onnxruntime/libonnxruntime.so`, where `scripts/setup.sh` installs it;
//! a library file that is cut short is refused before it is opened.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use lidar_har_core::activity::Activity;
use lidar_har_core::classifier::{StepModel, StreamSpec, StreamSpecError};
use ndarray::ArrayView2;
use ort::environment::Environment;
use ort::session::builder::GraphOptimizationLevel;
use ort::session::{Session, SessionOutputs};
use ort::value::{Outlet, TensorElementType, TensorRef};

mod pose_head;
mod runtime_library;

pub use pose_head::{KEY_ACTIVITY_SHA256, PoseHeadModel};

/// Where `scripts/setup.sh` puts the ONNX Runtime library, relative to the repository root.
pub const DEFAULT_RUNTIME_RELATIVE: &str = ".deps/onnxruntime/libonnxruntime.so";

#[derive(Debug, Clone, thiserror::Error)]
pub enum InferError {
    #[error(
        "ONNX Runtime library not found at {path} ({origin}); run scripts/setup.sh to install it, \
         or set ORT_DYLIB_PATH to a libonnxruntime.so of version 1.31"
    )]
    RuntimeMissing { path: PathBuf, origin: &'static str },
    #[error(
        "could not load ONNX Runtime from {path}: {message}; run scripts/setup.sh to reinstall it"
    )]
    RuntimeLoad { path: PathBuf, message: String },
    #[error(
        "ONNX Runtime library {} ({origin}) is a directory: name the .so file in it, e.g. \
         ORT_DYLIB_PATH={}",
        path.display(),
        path.join("libonnxruntime.so").display()
    )]
    RuntimeIsDirectory { path: PathBuf, origin: &'static str },
    #[error("cannot use ONNX Runtime library {path}: {problem}")]
    RuntimeUnusable { path: PathBuf, problem: String },
    #[error(
        "model file {}{} not found: the committed models are in models/ of the source tree and \
         share/lidar_har/models/ of an installed package; or train one (docs/training.md)",
        path.display(),
        relative_to_working_directory(path)
    )]
    ModelMissing { path: PathBuf },
    #[error("could not load model {path}: {message}")]
    ModelLoad { path: PathBuf, message: String },
    /// A thread count of 0, which ONNX Runtime would read as one thread per core: the
    /// caller's setting is wrong, not the model file.
    #[error(
        "ONNX Runtime intra-op threads must be at least 1, got 0 (loading {}): set the threads \
         option to 1 or more",
        path.display()
    )]
    ZeroThreads { path: PathBuf },
    #[error("model {path} does not follow docs/model_contract.md: {problem}")]
    Contract { path: PathBuf, problem: String },
    #[error("model {path} has unusable metadata: {cause}")]
    Metadata {
        path: PathBuf,
        cause: StreamSpecError,
    },
    #[error("frame is {got:?} pixels, the model takes {expected}x{expected}")]
    FrameShape {
        got: (usize, usize),
        expected: usize,
    },
    #[error("frame pixel ({row}, {column}) is {value}; the model takes finite values only")]
    FrameNotFinite {
        row: usize,
        column: usize,
        value: f32,
    },
    #[error(
        "state '{tensor}' has {found} values, but {model} takes a state of shape {expected:?} \
         ({} values): the state was made for another model",
        expected.iter().product::<usize>()
    )]
    StateMismatch {
        model: PathBuf,
        tensor: &'static str,
        expected: [usize; 4],
        found: usize,
    },
    #[error(
        "pose head {path} was fitted on another activity model (sha256 {fitted_on}), not on \
         {model} (sha256 {found}): fit one for this model (python -m lidar_har_train.pose_head) \
         or leave pose_head out of the classifier config"
    )]
    PoseHeadMismatch {
        path: PathBuf,
        model: PathBuf,
        fitted_on: String,
        found: String,
    },
    #[error(
        "model {} gave {value} in output '{output}' (value {index}): a broken model (a NaN or \
         an overflow in its weights or arithmetic); the step was refused and the state left \
         as it was",
        model.display()
    )]
    OutputNotFinite {
        model: PathBuf,
        output: &'static str,
        index: usize,
        value: f32,
    },
    #[error("ONNX Runtime failed to run the model: {0}")]
    Run(String),
}

impl InferError {
    /// Whether ONNX Runtime itself is missing or unusable (the installation), rather than
    /// the model.
    pub fn is_runtime(&self) -> bool {
        matches!(
            self,
            Self::RuntimeMissing { .. }
                | Self::RuntimeLoad { .. }
                | Self::RuntimeIsDirectory { .. }
                | Self::RuntimeUnusable { .. }
        )
    }
}

/// The library path to load and where that choice came from. A relative path is found as
/// `ort` finds it: next to the executable, else as `dlopen` takes it (a bare file name is
/// searched for by the system loader, a path with a slash is relative to the working
/// directory).
pub fn runtime_library_path() -> (PathBuf, &'static str) {
    match std::env::var_os("ORT_DYLIB_PATH") {
        Some(p) if !p.is_empty() => (PathBuf::from(p), "from ORT_DYLIB_PATH"),
        _ => (
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../..")
                .join(DEFAULT_RUNTIME_RELATIVE),
            "the default location; ORT_DYLIB_PATH is not set",
        ),
    }
}

/// The process-wide ONNX Runtime environment (ONNX Runtime allows one per process).
fn environment() -> Result<&'static Environment, InferError> {
    static ENV: OnceLock<Result<Environment, InferError>> = OnceLock::new();
    let result = ENV.get_or_init(|| {
        let (configured, origin) = runtime_library_path();
        let library = runtime_library::locate(&configured, origin)?;
        ort::init_from(library.path())
            .map_err(|e| e.to_string())
            .and_then(|builder| {
                builder
                    .with_name("lidar_har")
                    .build()
                    .map_err(|e| e.to_string())
            })
            .map_err(|message| InferError::RuntimeLoad {
                path: library.path().to_path_buf(),
                message: match library {
                    runtime_library::Library::ByLoader(_) => format!(
                        "{message} (a bare file name {origin}, not next to the executable: \
                         the system loader searched LD_LIBRARY_PATH and the system's library \
                         directories)"
                    ),
                    runtime_library::Library::File(_) => message,
                },
            })
    });
    result.as_ref().map_err(Clone::clone)
}

/// What a model file says about itself and its state.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelInfo {
    pub path: PathBuf,
    /// Representation, window and scan rate, from `metadata_props`.
    pub stream: StreamSpec,
    /// Hidden channels of the ConvLSTM state.
    pub hidden: usize,
    /// Side of the state's feature map.
    pub state_side: usize,
    /// Intra-op threads the session runs with.
    pub threads: usize,
}

/// The ConvLSTM state for one lane: `h` and `c`, `[1, hidden, side, side]` each.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelState {
    h: Vec<f32>,
    c: Vec<f32>,
}

impl ModelState {
    pub fn h(&self) -> &[f32] {
        &self.h
    }
    pub fn c(&self) -> &[f32] {
        &self.c
    }

    /// Refuses a state made by another model (of another shape) before ONNX Runtime sees it.
    fn check_fits(&self, expected: [usize; 4], model: &Path) -> Result<(), InferError> {
        let values: usize = expected.iter().product();
        for (tensor, data) in [("h", &self.h), ("c", &self.c)] {
            if data.len() != values {
                return Err(InferError::StateMismatch {
                    model: model.to_path_buf(),
                    tensor,
                    expected,
                    found: data.len(),
                });
            }
        }
        Ok(())
    }
}

/// A loaded step model.
pub struct ActivityModel {
    session: Session,
    info: ModelInfo,
    state_shape: [usize; 4],
    /// Copy of a frame that is not contiguous in memory (normally unused).
    frame_buffer: Vec<f32>,
}

impl std::fmt::Debug for ActivityModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ActivityModel")
            .field("info", &self.info)
            .finish_non_exhaustive()
    }
}

impl ActivityModel {
    /// Loads and checks a model; `threads` is ONNX Runtime's intra-op thread count (>= 1).
    pub fn load(path: impl AsRef<Path>, threads: usize) -> Result<Self, InferError> {
        let path = path.as_ref().to_path_buf();
        let env = environment()?;
        check_model_file(&path)?;
        let load_error = |message: String| InferError::ModelLoad {
            path: path.clone(),
            message,
        };
        let session = open_session(env, &path, threads)?;

        let metadata = session.metadata().map_err(|e| load_error(e.to_string()))?;
        let stream = StreamSpec::from_metadata(|key| metadata.custom(key)).map_err(|source| {
            InferError::Metadata {
                path: path.clone(),
                cause: source,
            }
        })?;
        drop(metadata);

        let contract = |problem: String| InferError::Contract {
            path: path.clone(),
            problem,
        };
        let (hidden, state_side) = check_signature(
            session.inputs(),
            session.outputs(),
            stream.representation.size,
        )
        .map_err(contract)?;
        Ok(Self {
            session,
            info: ModelInfo {
                path: path.clone(),
                stream,
                hidden,
                state_side,
                threads,
            },
            state_shape: [1, hidden, state_side, state_side],
            frame_buffer: Vec::new(),
        })
    }

    pub fn info(&self) -> &ModelInfo {
        &self.info
    }

    fn state_len(&self) -> usize {
        self.state_shape.iter().product()
    }

    /// One step: returns the logits and updates `state` in place. A refused frame or state,
    /// a failed run, or outputs that are not all finite leave `state` as it was.
    pub fn step(
        &mut self,
        frame: ArrayView2<'_, f32>,
        state: &mut ModelState,
    ) -> Result<[f32; Activity::COUNT], InferError> {
        let size = self.info.stream.representation.size;
        if frame.dim() != (size, size) {
            return Err(InferError::FrameShape {
                got: frame.dim(),
                expected: size,
            });
        }
        state.check_fits(self.state_shape, &self.info.path)?;
        let frame_data: &[f32] = match frame.as_slice() {
            Some(data) => data,
            None => {
                self.frame_buffer.clear();
                self.frame_buffer.extend(frame.iter());
                &self.frame_buffer
            }
        };
        // One NaN would stay in the recurrent state and make every later output NaN.
        if let Some(at) = frame_data.iter().position(|v| !v.is_finite()) {
            return Err(InferError::FrameNotFinite {
                row: at / size,
                column: at % size,
                value: frame_data[at],
            });
        }
        let run = |e: ort::Error| InferError::Run(e.to_string());
        let inputs = ort::inputs![
            "frame" => TensorRef::from_array_view(([1usize, 1, size, size], frame_data)).map_err(run)?,
            "h" => TensorRef::from_array_view((self.state_shape, state.h.as_slice())).map_err(run)?,
            "c" => TensorRef::from_array_view((self.state_shape, state.c.as_slice())).map_err(run)?,
        ];
        let outputs = self.session.run(inputs).map_err(run)?;
        let logits_out = output_values(&outputs, "the model", "logits", Activity::COUNT)?;
        let h_next = output_values(&outputs, "the model", "h_next", state.h.len())?;
        let c_next = output_values(&outputs, "the model", "c_next", state.c.len())?;
        // A NaN or infinity kept in the state would make every later output of the lane NaN,
        // and NaN logits were published as the uniform distribution's first class
        // (crawling at 11 %): refuse the step before anything is copied.
        for (output, values) in [
            ("logits", logits_out),
            ("h_next", h_next),
            ("c_next", c_next),
        ] {
            if let Some(index) = values.iter().position(|v| !v.is_finite()) {
                return Err(InferError::OutputNotFinite {
                    model: self.info.path.clone(),
                    output,
                    index,
                    value: values[index],
                });
            }
        }
        let mut logits = [0.0; Activity::COUNT];
        logits.copy_from_slice(logits_out);
        state.h.copy_from_slice(h_next);
        state.c.copy_from_slice(c_next);
        Ok(logits)
    }
}

/// The values of the float output `name` of a run, which must hold exactly `len` of them.
fn output_values<'a>(
    outputs: &'a SessionOutputs<'_>,
    model: &str,
    name: &str,
    len: usize,
) -> Result<&'a [f32], InferError> {
    let value = outputs
        .get(name)
        .ok_or_else(|| InferError::Run(format!("{model} gave no '{name}' output")))?;
    let (_, data) = value
        .try_extract_tensor::<f32>()
        .map_err(|e| InferError::Run(e.to_string()))?;
    if data.len() != len {
        return Err(InferError::Run(format!(
            "output '{name}' has {} values, expected {len}",
            data.len()
        )));
    }
    Ok(data)
}

impl StepModel for ActivityModel {
    type State = ModelState;
    type Error = InferError;

    fn initial_state(&self) -> ModelState {
        ModelState {
            h: vec![0.0; self.state_len()],
            c: vec![0.0; self.state_len()],
        }
    }

    fn reset_state(&self, state: &mut ModelState) {
        state.h.fill(0.0);
        state.c.fill(0.0);
    }

    fn step(
        &mut self,
        frame: ArrayView2<'_, f32>,
        state: &mut ModelState,
    ) -> Result<[f32; Activity::COUNT], InferError> {
        ActivityModel::step(self, frame, state)
    }
}

/// A model path must name a file: a missing one says where it was looked for.
fn check_model_file(path: &Path) -> Result<(), InferError> {
    if path.is_dir() {
        return Err(InferError::ModelLoad {
            path: path.to_path_buf(),
            message: "it is a directory, not an ONNX file".into(),
        });
    }
    if !path.is_file() {
        return Err(InferError::ModelMissing {
            path: path.to_path_buf(),
        });
    }
    Ok(())
}

/// " (relative to DIR)" for a relative path: a node's working directory is not obvious.
fn relative_to_working_directory(path: &Path) -> String {
    match std::env::current_dir() {
        Ok(dir) if path.is_relative() => format!(" (relative to {})", dir.display()),
        _ => String::new(),
    }
}

/// An ONNX Runtime session on the model file at `path` with `threads` intra-op threads.
fn open_session(env: &Environment, path: &Path, threads: usize) -> Result<Session, InferError> {
    let load_error = |message: String| InferError::ModelLoad {
        path: path.to_path_buf(),
        message,
    };
    // ONNX Runtime would read 0 as "its default", one thread per core.
    if threads == 0 {
        return Err(InferError::ZeroThreads {
            path: path.to_path_buf(),
        });
    }
    Session::builder(env)
        .map_err(|e| load_error(e.to_string()))?
        .with_optimization_level(GraphOptimizationLevel::Level3)
        .map_err(|e| load_error(e.to_string()))?
        .with_intra_threads(threads)
        .map_err(|e| load_error(e.to_string()))?
        .with_inter_threads(1)
        .map_err(|e| load_error(e.to_string()))?
        .commit_from_file(path)
        .map_err(|e| load_error(e.to_string()))
}

/// The shape of the float32 tensor `name` among `outlets` (`kind`: "input" or "output");
/// an error names what is missing or of another type.
fn float_outlet_shape(outlets: &[Outlet], kind: &str, name: &str) -> Result<Vec<i64>, String> {
    let names: Vec<&str> = outlets.iter().map(|o| o.name()).collect();
    let outlet = outlets
        .iter()
        .find(|o| o.name() == name)
        .ok_or_else(|| format!("no {kind} named '{name}' (the model's {kind}s: {names:?})"))?;
    if outlet.dtype().tensor_type() != Some(TensorElementType::Float32) {
        return Err(format!(
            "{kind} '{name}' is {}, expected a float32 tensor",
            outlet.dtype()
        ));
    }
    Ok(outlet
        .dtype()
        .tensor_shape()
        .map(|s| s.to_vec())
        .unwrap_or_default())
}

/// Whether `outlets` hold exactly the tensors `expected` (float32), no more.
fn check_outlet_names(outlets: &[Outlet], kind: &str, expected: &[&str]) -> Result<(), String> {
    for name in expected {
        float_outlet_shape(outlets, kind, name)?;
    }
    match outlets.iter().find(|o| !expected.contains(&o.name())) {
        Some(extra) => Err(format!(
            "unexpected {kind} '{}' (expected exactly {expected:?})",
            extra.name()
        )),
        None => Ok(()),
    }
}

/// Whether a model's `shape` is `expected`; the batch dimension may be symbolic (-1).
fn shape_matches(shape: &[i64], expected: &[usize]) -> bool {
    shape.len() == expected.len()
        && shape
            .iter()
            .zip(expected)
            .enumerate()
            .all(|(i, (&got, &want))| got == want as i64 || (i == 0 && got == -1))
}

/// The largest recurrent state accepted (values of 'h'): 64 MB of floats, thousands of times
/// the committed model's.
const MAX_STATE_VALUES: usize = 1 << 24;

/// The recurrent state's (hidden, side) from the declared shape of 'h', `[1, hidden, side,
/// side]` with fixed sizes.
fn state_dims(h: &[i64]) -> Result<(usize, usize), String> {
    let (hidden, side) = match h {
        [_, hidden, side, side2] if *hidden > 0 && side == side2 && *side > 0 => {
            (*hidden as usize, *side as usize)
        }
        _ => {
            return Err(format!(
                "input 'h' has shape {h:?}, expected [1, hidden, side, side] with fixed sizes"
            ));
        }
    };
    // A broken file may declare any size: refuse one that could not be allocated twice per
    // lane rather than abort on it.
    let values = hidden.checked_mul(side).and_then(|n| n.checked_mul(side));
    if values.is_none_or(|n| n > MAX_STATE_VALUES) {
        return Err(format!(
            "input 'h' has shape {h:?}: a state of more than {MAX_STATE_VALUES} values is not \
             a lidar_har model"
        ));
    }
    Ok((hidden, side))
}

/// Checks names, element types and shapes against the contract; returns (hidden, state side).
fn check_signature(
    inputs: &[Outlet],
    outputs: &[Outlet],
    size: usize,
) -> Result<(usize, usize), String> {
    check_outlet_names(inputs, "input", &["frame", "h", "c"])?;
    check_outlet_names(outputs, "output", &["logits", "h_next", "c_next"])?;
    let frame = float_outlet_shape(inputs, "input", "frame")?;
    if !shape_matches(&frame, &[1, 1, size, size]) {
        return Err(format!(
            "input 'frame' has shape {frame:?}, expected [1, 1, {size}, {size}] (lidar_har.size = {size} in the metadata)"
        ));
    }
    let h = float_outlet_shape(inputs, "input", "h")?;
    let (hidden, side) = state_dims(&h)?;
    let state_shape = [1, hidden, side, side];
    for (name, kind, outlets) in [
        ("h", "input", inputs),
        ("c", "input", inputs),
        ("h_next", "output", outputs),
        ("c_next", "output", outputs),
    ] {
        let shape = float_outlet_shape(outlets, kind, name)?;
        if !shape_matches(&shape, &state_shape) {
            return Err(format!(
                "{kind} '{name}' has shape {shape:?}, expected {state_shape:?} (the shape of 'h')"
            ));
        }
    }
    let logits = float_outlet_shape(outputs, "output", "logits")?;
    if !shape_matches(&logits, &[1, Activity::COUNT]) {
        return Err(format!(
            "output 'logits' has shape {logits:?}, expected [1, {}] (one per activity class)",
            Activity::COUNT
        ));
    }
    Ok((hidden, side))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_state_shape_must_be_square_fixed_and_of_a_size_that_can_be_held() {
        assert_eq!(state_dims(&[1, 32, 8, 8]), Ok((32, 8)));
        assert_eq!(state_dims(&[-1, 32, 8, 8]), Ok((32, 8)));
        for bad in [&[1, 32, 8, 4][..], &[1, -1, 8, 8], &[1, 32, 8]] {
            let e = state_dims(bad).unwrap_err();
            assert!(
                e.contains("expected [1, hidden, side, side]"),
                "{bad:?}: {e}"
            );
        }
        // Used to allocate (or overflow to) whatever the file declared.
        for huge in [
            &[1, 1 << 20, 1 << 20, 1 << 20][..],
            &[1, i64::MAX, i64::MAX, i64::MAX],
        ] {
            let e = state_dims(huge).unwrap_err();
            assert!(e.contains("not a lidar_har model"), "{huge:?}: {e}");
        }
    }
}
