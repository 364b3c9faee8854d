//! The pose head on ONNX Runtime (docs/model_contract.md, "Pose head"): a second, small
//! model that reads the activity model's state, bound by checksum to the activity model it
//! was fitted on.

use std::path::{Path, PathBuf};

use glam::DVec2;
use lidar_har_core::pose_head::{HeadEstimate, PoseHead, PoseHeadSpec};
use ort::session::Session;
use ort::value::{Outlet, TensorRef};
use sha2::{Digest, Sha256};

use crate::{
    ActivityModel, InferError, ModelState, check_model_file, check_outlet_names, environment,
    float_outlet_shape, open_session, output_values, shape_matches,
};

/// Metadata key: the SHA-256 (hex) of the activity model file whose state the head reads.
pub const KEY_ACTIVITY_SHA256: &str = "lidar_har.pose_head.activity_sha256";

/// A loaded pose head.
pub struct PoseHeadModel {
    session: Session,
    path: PathBuf,
    spec: PoseHeadSpec,
    state_shape: [usize; 4],
}

impl std::fmt::Debug for PoseHeadModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PoseHeadModel")
            .field("path", &self.path)
            .field("spec", &self.spec)
            .finish_non_exhaustive()
    }
}

impl PoseHeadModel {
    /// Loads the head at `path` and checks it against the contract and against `activity`:
    /// it must read that model's state and have been fitted on that very file.
    pub fn load(
        path: impl AsRef<Path>,
        activity: &ActivityModel,
        threads: usize,
    ) -> Result<Self, InferError> {
        let path = path.as_ref().to_path_buf();
        let env = environment()?;
        check_model_file(&path)?;
        let session = open_session(env, &path, threads)?;
        let metadata = session.metadata().map_err(|e| InferError::ModelLoad {
            path: path.clone(),
            message: e.to_string(),
        })?;
        let spec = PoseHeadSpec::from_metadata(|key| metadata.custom(key)).map_err(|cause| {
            InferError::Metadata {
                path: path.clone(),
                cause,
            }
        })?;
        let fitted_on = metadata.custom(KEY_ACTIVITY_SHA256);
        drop(metadata);

        let info = activity.info();
        let state_shape = [1, info.hidden, info.state_side, info.state_side];
        check_signature(session.inputs(), session.outputs(), state_shape).map_err(|problem| {
            InferError::Contract {
                path: path.clone(),
                problem,
            }
        })?;
        let fitted_on = fitted_on.ok_or_else(|| InferError::Contract {
            path: path.clone(),
            problem: format!("metadata key '{KEY_ACTIVITY_SHA256}' is missing"),
        })?;
        let model_bytes = std::fs::read(&info.path).map_err(|e| InferError::ModelLoad {
            path: info.path.clone(),
            message: e.to_string(),
        })?;
        let found = format!("{:x}", Sha256::digest(&model_bytes));
        // Hex is hex in either case: an exporter that writes it in upper case fitted the head
        // on this very model.
        let fitted_on = fitted_on.trim();
        if !fitted_on.eq_ignore_ascii_case(&found) {
            return Err(InferError::PoseHeadMismatch {
                path,
                model: info.path.clone(),
                fitted_on: fitted_on.to_string(),
                found,
            });
        }
        Ok(Self {
            session,
            path,
            spec,
            state_shape,
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Where the head may be used (from its metadata).
    pub fn spec(&self) -> &PoseHeadSpec {
        &self.spec
    }
}

impl PoseHead<ModelState> for PoseHeadModel {
    type Error = InferError;

    fn estimate(&mut self, state: &ModelState, located: DVec2) -> Result<HeadEstimate, InferError> {
        state.check_fits(self.state_shape, &self.path)?;
        let run = |e: ort::Error| InferError::Run(e.to_string());
        let located = [located.x as f32, located.y as f32];
        let inputs = ort::inputs![
            "h" => TensorRef::from_array_view((self.state_shape, state.h())).map_err(run)?,
            "located" => TensorRef::from_array_view(([1usize, 2], &located[..])).map_err(run)?,
        ];
        let outputs = self.session.run(inputs).map_err(run)?;
        // Not checked for finiteness here: a state the head doubts without bound is the
        // placer's to leave out (`lidar_har_core::pose_head`), not an error.
        let offset = output_values(&outputs, "the pose head", "offset", 2)?;
        let sigma = output_values(&outputs, "the pose head", "sigma", 1)?;
        Ok(HeadEstimate {
            offset: DVec2::new(f64::from(offset[0]), f64::from(offset[1])),
            sigma_m: f64::from(sigma[0]),
        })
    }
}

/// Inputs `h` (the activity model's state shape) and `located` `[1, 2]`, outputs `offset`
/// `[1, 2]` and `sigma` `[1, 1]`, all float32.
fn check_signature(
    inputs: &[Outlet],
    outputs: &[Outlet],
    state_shape: [usize; 4],
) -> Result<(), String> {
    check_outlet_names(inputs, "input", &["h", "located"])?;
    check_outlet_names(outputs, "output", &["offset", "sigma"])?;
    for (outlets, kind, name, expected) in [
        (inputs, "input", "h", &state_shape[..]),
        (inputs, "input", "located", &[1, 2]),
        (outputs, "output", "offset", &[1, 2]),
        (outputs, "output", "sigma", &[1, 1]),
    ] {
        let shape = float_outlet_shape(outlets, kind, name)?;
        if !shape_matches(&shape, expected) {
            return Err(format!(
                "{kind} '{name}' has shape {shape:?}, expected {expected:?} (for 'h': the activity model's state)"
            ));
        }
    }
    Ok(())
}
