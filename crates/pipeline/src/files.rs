//! Reading the localiser's inputs from files: its YAML configuration and map_server maps
//! (a YAML file naming a PGM or PNG image). Every error names the file and what is wrong.

use std::path::{Path, PathBuf};

use lidar_har_core::geometry::Pose2;
use lidar_har_core::localiser::{ConfigError, LocaliserConfig};
use lidar_har_core::map::{MAP_SERVER_OCCUPIED_THRESH, MapError, MapGeometry, OccupancyMap};
use serde::Deserialize;

/// Why a configuration or map file cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum FileError {
    #[error("cannot read {}: {cause}", path.display())]
    Read {
        path: PathBuf,
        cause: std::io::Error,
    },
    #[error("{} is not a valid {what}: {cause}", path.display())]
    Yaml {
        path: PathBuf,
        what: &'static str,
        cause: serde_yaml_ng::Error,
    },
    #[error("{}: {cause}", path.display())]
    Config { path: PathBuf, cause: ConfigError },
    #[error("cannot load map image {}: {cause}", path.display())]
    Image {
        path: PathBuf,
        cause: image::ImageError,
    },
    #[error("map {}: {why}", path.display())]
    MapSpec { path: PathBuf, why: String },
    #[error("map {}: {cause}", path.display())]
    Map { path: PathBuf, cause: MapError },
}

/// Loads a localiser configuration (`config/localiser.yaml`); unknown keys are errors, and
/// keys left out take the paper's defaults.
pub fn load_localiser_config(path: &Path) -> Result<LocaliserConfig, FileError> {
    let text = std::fs::read_to_string(path).map_err(|source| FileError::Read {
        path: path.into(),
        cause: source,
    })?;
    parse_localiser_config(&text).map_err(|e| match e {
        ParseConfigError::Yaml(source) => FileError::Yaml {
            path: path.into(),
            what: "localiser configuration",
            cause: source,
        },
        ParseConfigError::Invalid(source) => FileError::Config {
            path: path.into(),
            cause: source,
        },
    })
}

/// Why configuration text cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum ParseConfigError {
    #[error(transparent)]
    Yaml(#[from] serde_yaml_ng::Error),
    #[error(transparent)]
    Invalid(#[from] ConfigError),
}

/// Parses and validates configuration text (also used for ROS parameter values).
pub fn parse_localiser_config(text: &str) -> Result<LocaliserConfig, ParseConfigError> {
    let config: LocaliserConfig = serde_yaml_ng::from_str(text)?;
    config.validate()?;
    Ok(config)
}

/// map_server's YAML map description (ROS 2 nav2_map_server format).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct MapSpec {
    image: PathBuf,
    resolution: f64,
    origin: [f64; 3],
    #[serde(default = "default_occupied_thresh")]
    occupied_thresh: f64,
    #[serde(default = "default_free_thresh")]
    free_thresh: f64,
    #[serde(default)]
    negate: Flag,
    #[serde(default)]
    mode: MapMode,
}

fn default_occupied_thresh() -> f64 {
    MAP_SERVER_OCCUPIED_THRESH
}

fn default_free_thresh() -> f64 {
    0.196
}

/// map_server writes `negate: 0`; hand-written files often say `false`.
#[derive(Debug, Default, Deserialize)]
#[serde(untagged)]
enum Flag {
    Bool(bool),
    Int(i64),
    #[default]
    Unset,
}

impl Flag {
    fn is_set(&self) -> bool {
        matches!(self, Flag::Bool(true)) || matches!(self, Flag::Int(i) if *i != 0)
    }
}

#[derive(Debug, Default, Deserialize, PartialEq)]
#[serde(rename_all = "lowercase")]
enum MapMode {
    #[default]
    Trinary,
    Scale,
    Raw,
}

/// Loads a map_server map: the YAML file and the image it names (relative to the YAML).
/// A cell is an obstacle when its occupancy (from the pixel's darkness, or the pixel value
/// itself in `raw` mode) exceeds `occupied_thresh`, as map_server decides.
pub fn load_map(yaml_path: &Path) -> Result<OccupancyMap, FileError> {
    let path = || yaml_path.to_path_buf();
    let text = std::fs::read_to_string(yaml_path).map_err(|source| FileError::Read {
        path: path(),
        cause: source,
    })?;
    let spec: MapSpec = serde_yaml_ng::from_str(&text).map_err(|source| FileError::Yaml {
        path: path(),
        what: "map_server map",
        cause: source,
    })?;
    let thresholds_ok = (0.0..=1.0).contains(&spec.occupied_thresh)
        && (0.0..=1.0).contains(&spec.free_thresh)
        && spec.free_thresh <= spec.occupied_thresh;
    if !thresholds_ok {
        return Err(FileError::MapSpec {
            path: path(),
            why: format!(
                "thresholds must satisfy 0 <= free_thresh ({}) <= occupied_thresh ({}) <= 1",
                spec.free_thresh, spec.occupied_thresh
            ),
        });
    }
    if spec.origin.iter().any(|v| !v.is_finite()) {
        return Err(FileError::MapSpec {
            path: path(),
            why: format!("origin {:?} is not finite", spec.origin),
        });
    }
    let image_path = yaml_path
        .parent()
        .unwrap_or(Path::new("."))
        .join(&spec.image);
    let image = image::open(&image_path)
        .map_err(|source| FileError::Image {
            path: image_path.clone(),
            cause: source,
        })?
        .to_luma8();
    let (width, height) = (image.width() as usize, image.height() as usize);
    let mut occupied = vec![false; width * height];
    let mut unknown = vec![false; width * height];
    for (x, y, pixel) in image.enumerate_pixels() {
        let value = f64::from(pixel.0[0]);
        let occupancy = match (spec.mode == MapMode::Raw, spec.negate.is_set()) {
            (true, _) => value / 100.0,
            (false, true) => value / 255.0,
            (false, false) => (255.0 - value) / 255.0,
        };
        // Image row 0 is the top of the map, grid row 0 its bottom (at the origin).
        let row = height - 1 - y as usize;
        let cell = row * width + x as usize;
        occupied[cell] = occupancy > spec.occupied_thresh;
        // map_server: between the thresholds is unknown; in raw mode, values above 100 are.
        unknown[cell] = if spec.mode == MapMode::Raw {
            value > 100.0
        } else {
            !occupied[cell] && occupancy >= spec.free_thresh
        };
    }
    let [x, y, theta] = spec.origin;
    let geometry = MapGeometry {
        resolution: spec.resolution,
        origin: Pose2::new(x, y, theta),
        width,
        height,
    };
    OccupancyMap::with_unknown(geometry, occupied, unknown).map_err(|source| FileError::Map {
        path: path(),
        cause: source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec2;

    fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    }

    /// A 4 x 3 binary PGM: black (occupied) pixel at the top-left, grey (unknown) at the
    /// bottom-right, the rest white (free).
    fn pgm() -> Vec<u8> {
        let mut bytes = b"P5\n4 3\n255\n".to_vec();
        let mut pixels = [254u8; 12];
        pixels[0] = 0;
        pixels[11] = 205;
        bytes.extend_from_slice(&pixels);
        bytes
    }

    #[test]
    fn map_server_map_loads_with_rows_flipped() {
        let dir = tempfile::tempdir().unwrap();
        write(dir.path(), "room.pgm", &pgm());
        let yaml = write(
            dir.path(),
            "room.yaml",
            b"image: room.pgm\nresolution: 0.5\norigin: [-1.0, -1.0, 0.0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n",
        );
        let map = load_map(&yaml).unwrap();
        assert_eq!((map.geometry().width, map.geometry().height), (4, 3));
        assert_eq!(map.occupied_cells(), 1);
        assert!(
            map.is_occupied(0, 2),
            "top-left pixel is the top row of the grid"
        );
        // Centre of that cell in the map frame: (-1 + 0.25, -1 + 1.25).
        assert_eq!(map.distance_to_obstacle(DVec2::new(-0.75, 0.25)), Some(0.0));
        // The grey pixel (bottom-right of the image: grid row 0, column 3) is unknown.
        assert!(map.is_unknown(3, 0));
        assert!(!map.is_unknown(2, 0) && !map.is_unknown(0, 2));
    }

    #[test]
    fn negate_inverts_the_image() {
        let dir = tempfile::tempdir().unwrap();
        write(dir.path(), "room.pgm", &pgm());
        let yaml = write(
            dir.path(),
            "room.yaml",
            b"image: room.pgm\nresolution: 0.5\norigin: [0, 0, 0]\nnegate: true\n",
        );
        assert_eq!(load_map(&yaml).unwrap().occupied_cells(), 11);
    }

    #[test]
    fn missing_and_garbled_files_say_which_and_why() {
        let dir = tempfile::tempdir().unwrap();
        let err = load_map(&dir.path().join("nope.yaml")).unwrap_err();
        assert!(
            matches!(err, FileError::Read { .. }) && err.to_string().contains("nope.yaml"),
            "{err}"
        );

        let yaml = write(
            dir.path(),
            "a.yaml",
            b"image: missing.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n",
        );
        let err = load_map(&yaml).unwrap_err();
        assert!(
            matches!(err, FileError::Image { .. }) && err.to_string().contains("missing.pgm"),
            "{err}"
        );

        write(dir.path(), "bad.pgm", b"P5\n4 3\n255\n\x00\x01");
        let yaml = write(
            dir.path(),
            "b.yaml",
            b"image: bad.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n",
        );
        assert!(matches!(
            load_map(&yaml).unwrap_err(),
            FileError::Image { .. }
        ));

        let yaml = write(
            dir.path(),
            "c.yaml",
            b"image: room.pgm\nresolution: [1, 2]\n",
        );
        let err = load_map(&yaml).unwrap_err();
        assert!(matches!(err, FileError::Yaml { .. }), "{err}");

        write(dir.path(), "room.pgm", &pgm());
        let yaml = write(
            dir.path(),
            "d.yaml",
            b"image: room.pgm\nresolution: -1\norigin: [0, 0, 0]\n",
        );
        assert!(matches!(
            load_map(&yaml).unwrap_err(),
            FileError::Map {
                cause: MapError::Resolution(_),
                ..
            }
        ));

        let yaml = write(
            dir.path(),
            "e.yaml",
            b"image: room.pgm\nresolution: 1\norigin: [0, 0, 0]\noccupied_thresh: 0.1\nfree_thresh: 0.5\n",
        );
        assert!(matches!(
            load_map(&yaml).unwrap_err(),
            FileError::MapSpec { .. }
        ));
    }

    #[test]
    fn the_shipped_config_is_the_paper_defaults() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/localiser.yaml");
        assert_eq!(
            load_localiser_config(&path).unwrap(),
            LocaliserConfig::default()
        );
    }

    #[test]
    fn config_errors_name_the_problem() {
        let err = parse_localiser_config("obstacle_margin: 0.2\n").unwrap_err();
        assert!(
            err.to_string().contains("unknown field `obstacle_margin`"),
            "{err}"
        );
        let err = parse_localiser_config("tracker:\n  gate_m: -0.8\n").unwrap_err();
        assert!(err.to_string().contains("tracker.gate_m"), "{err}");
        let partial = parse_localiser_config("tracker:\n  gate_m: 1.0\n").unwrap();
        assert_eq!(partial.tracker.gate_m, 1.0);
        assert_eq!(partial.obstacle_margin_m, 0.2);
    }
}
