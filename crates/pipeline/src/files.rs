//! Reading the localiser's inputs from files: its YAML configuration and map_server maps
//! (a YAML file naming a PGM or PNG image). Every error names the file and what is wrong.

use std::path::{Path, PathBuf};

use std::collections::BTreeMap;

use image::{DynamicImage, ImageBuffer, Pixel, Primitive, Rgba};
use lidar_har_core::geometry::Pose2;
use lidar_har_core::localiser::{ConfigError, LocaliserConfig};
use lidar_har_core::map::{MAP_SERVER_OCCUPIED_THRESH, MapError, MapGeometry, OccupancyMap};
use serde::de::{Error as _, IgnoredAny};
use serde::{Deserialize, Deserializer};

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

/// map_server's YAML map description (ROS 2 nav2_map_server format). Other keys are ignored
/// with a warning, as nav2 ignores them: forks add their own (`name`, `elevation_image`...).
#[derive(Debug, Deserialize)]
struct MapSpec {
    image: PathBuf,
    resolution: f64,
    origin: [f64; 3],
    #[serde(default = "default_occupied_thresh")]
    occupied_thresh: f64,
    #[serde(default = "default_free_thresh")]
    free_thresh: f64,
    #[serde(default, deserialize_with = "negate_flag")]
    negate: bool,
    #[serde(default)]
    mode: MapMode,
    #[serde(flatten)]
    other: BTreeMap<String, IgnoredAny>,
}

fn default_occupied_thresh() -> f64 {
    MAP_SERVER_OCCUPIED_THRESH
}

fn default_free_thresh() -> f64 {
    0.196
}

/// `negate` as nav2 reads it with yaml-cpp: an integer (non-zero is true), else a YAML 1.1
/// boolean, whether or not the scalar is quoted. map_server writes `negate: 0`, hand-written
/// files say `false`, `yes` or `"0"`; `0.0` is neither to yaml-cpp, so nav2 refuses it too.
fn negate_flag<'de, D: Deserializer<'de>>(deserializer: D) -> Result<bool, D::Error> {
    let value = serde_yaml_ng::Value::deserialize(deserializer)?;
    let flag = match &value {
        serde_yaml_ng::Value::Bool(b) => Some(*b),
        serde_yaml_ng::Value::Number(n) => n
            .as_i64()
            .and_then(|i| i32::try_from(i).ok())
            .map(|i| i != 0),
        serde_yaml_ng::Value::String(s) => {
            yaml_cpp_int(s).map(|i| i != 0).or_else(|| yaml_cpp_bool(s))
        }
        _ => None,
    };
    flag.ok_or_else(|| {
        let given = match &value {
            serde_yaml_ng::Value::Sequence(_) => "a list".to_owned(),
            serde_yaml_ng::Value::Mapping(_) => "a mapping".to_owned(),
            scalar => serde_yaml_ng::to_string(scalar)
                .unwrap_or_default()
                .trim_end()
                .to_owned(),
        };
        D::Error::custom(format!(
            "negate must be an integer (0 or 1) or a boolean (true/false, yes/no, on/off), not {given}"
        ))
    })
}

/// yaml-cpp's `int`: the whole scalar, trailing spaces aside, read by a C++ stream that takes
/// a sign and then `0x` for hexadecimal, a leading `0` for octal or decimal digits.
fn yaml_cpp_int(text: &str) -> Option<i32> {
    let text = text.trim_end();
    let (negative, unsigned) = match text.strip_prefix('-') {
        Some(rest) => (true, rest),
        None => (false, text.strip_prefix('+').unwrap_or(text)),
    };
    let (radix, digits) = match unsigned.strip_prefix("0x").or(unsigned.strip_prefix("0X")) {
        Some(hex) => (16, hex),
        None if unsigned.len() > 1 && unsigned.starts_with('0') => (8, &unsigned[1..]),
        None => (10, unsigned),
    };
    // `from_str_radix` would take a second sign.
    if digits.is_empty() || !digits.chars().all(|c| c.is_digit(radix)) {
        return None;
    }
    let magnitude = i64::from_str_radix(digits, radix).ok()?;
    i32::try_from(if negative { -magnitude } else { magnitude }).ok()
}

/// yaml-cpp's `bool`: y/yes/true/on and n/no/false/off, in lower case, upper case or
/// capitalised.
fn yaml_cpp_bool(text: &str) -> Option<bool> {
    let lower = text.to_lowercase();
    let capitalised = lower
        .chars()
        .take(1)
        .flat_map(char::to_uppercase)
        .chain(lower.chars().skip(1))
        .collect::<String>();
    if text != lower && text != text.to_uppercase() && text != capitalised {
        return None;
    }
    match lower.as_str() {
        "y" | "yes" | "true" | "on" => Some(true),
        "n" | "no" | "false" | "off" => Some(false),
        _ => None,
    }
}

#[derive(Debug, Default, PartialEq)]
enum MapMode {
    #[default]
    Trinary,
    Scale,
    Raw,
}

/// nav2 lowercases the mode before naming it (`map_mode_from_string`): `Trinary` is trinary.
impl<'de> Deserialize<'de> for MapMode {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let mode = String::deserialize(deserializer)?;
        match mode.to_lowercase().as_str() {
            "trinary" => Ok(MapMode::Trinary),
            "scale" => Ok(MapMode::Scale),
            "raw" => Ok(MapMode::Raw),
            _ => Err(D::Error::custom(format!(
                "mode must be trinary, scale or raw, not {mode}"
            ))),
        }
    }
}

/// Loads a map_server map: the YAML file and the image it names (relative to the YAML).
/// Each pixel becomes the value nav2's map_server would publish for it on /map
/// ([`map_server_value`]), and the grid is read as a /map grid is
/// ([`OccupancyMap::from_grid_values`] with [`MAP_SERVER_OCCUPIED_THRESH`]): the same room
/// with `--map` as from the bag's /map that map_server published from the same file.
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
    for key in spec.other.keys() {
        log::warn!(
            "map {}: ignoring key `{key}`, which nav2's map_server does not read either",
            yaml_path.display()
        );
    }
    if spec.image.as_os_str().is_empty() {
        return Err(FileError::MapSpec {
            path: path(),
            why: "the image tag is empty".into(),
        });
    }
    let image_path = yaml_path
        .parent()
        .unwrap_or(Path::new("."))
        .join(&spec.image);
    let image_error = |cause| FileError::Image {
        path: image_path.clone(),
        cause,
    };
    // By content, as nav2's GraphicsMagick reads it: PNG bytes in a `.pgm`, or no extension.
    let image = image::ImageReader::open(&image_path)
        .and_then(|reader| reader.with_guessed_format())
        .map_err(|e| image_error(e.into()))?
        .decode()
        .map_err(image_error)?;
    let (width, height) = (image.width() as usize, image.height() as usize);
    if width == 0 || height == 0 {
        return Err(FileError::Map {
            path: path(),
            cause: MapError::Empty { width, height },
        });
    }
    // The image goes before the map is built: it can take 8 bytes a cell.
    let values = grid_values(image, &spec);
    let [x, y, theta] = spec.origin;
    let geometry = MapGeometry {
        resolution: spec.resolution,
        origin: Pose2::new(x, y, theta),
        width,
        height,
    };
    OccupancyMap::from_grid_values(geometry, &values, MAP_SERVER_OCCUPIED_THRESH).map_err(
        |source| FileError::Map {
            path: path(),
            cause: source,
        },
    )
}

/// The /map values of `image` (row-major, grid row 0 at the bottom of the image), from
/// its pixels at 16 bits whatever their depth: GraphicsMagick's quantum in nav2's builds, so a
/// 16-bit image is thresholded at its full depth rather than cut to 8 bits first.
fn grid_values(image: DynamicImage, spec: &MapSpec) -> Vec<i8> {
    let has_alpha = image.color().has_alpha();
    match image {
        DynamicImage::ImageLuma8(i) => pixel_values(&i, has_alpha, spec),
        DynamicImage::ImageLumaA8(i) => pixel_values(&i, has_alpha, spec),
        DynamicImage::ImageRgb8(i) => pixel_values(&i, has_alpha, spec),
        DynamicImage::ImageRgba8(i) => pixel_values(&i, has_alpha, spec),
        DynamicImage::ImageLuma16(i) => pixel_values(&i, has_alpha, spec),
        DynamicImage::ImageLumaA16(i) => pixel_values(&i, has_alpha, spec),
        DynamicImage::ImageRgb16(i) => pixel_values(&i, has_alpha, spec),
        DynamicImage::ImageRgba16(i) => pixel_values(&i, has_alpha, spec),
        // Floating-point images: none of the enabled formats decodes to them.
        other => pixel_values(&other.to_rgba16(), has_alpha, spec),
    }
}

fn pixel_values<P>(
    image: &ImageBuffer<P, Vec<P::Subpixel>>,
    has_alpha: bool,
    spec: &MapSpec,
) -> Vec<i8>
where
    P: Pixel,
    P::Subpixel: Into<u16>,
{
    // 257 for 8-bit channels (GraphicsMagick's ScaleCharToQuantum), 1 for 16-bit ones.
    let scale = u16::MAX / P::Subpixel::DEFAULT_MAX_VALUE.into();
    let (width, height) = (image.width() as usize, image.height() as usize);
    let mut values = vec![0i8; width * height];
    for (x, y, pixel) in image.enumerate_pixels() {
        let Rgba(channels) = pixel.to_rgba();
        let quantum = Rgba(channels.map(|c| c.into() * scale));
        // Image row 0 is the top of the map, grid row 0 its bottom (at the origin).
        let row = height - 1 - y as usize;
        values[row * width + x as usize] = map_server_value(quantum, has_alpha, spec);
    }
    values
}

/// The /map value (0..=100 occupancy in percent, -1 unknown) nav2's map_server publishes
/// for `pixel` (16-bit quanta) of an image with or without an alpha channel (its `map_io`):
/// the pixel's shade is the mean of its colour channels (and, in trinary mode only, its
/// opacity when the image has an alpha channel), its occupancy that shade's darkness (its
/// brightness with `negate`), and then
/// - trinary: above `occupied_thresh` 100, below `free_thresh` 0, else unknown;
/// - scale: a pixel not fully opaque unknown, above and below the thresholds as in
///   trinary, in between scaled linearly from 0 to 100 (a grey floor is free, not unknown);
/// - raw: the shade itself on 0..=255, rounded (`negate` and the thresholds unused), above
///   100 unknown.
///
/// The mean, not the luminance these files were once read with, so a colour image loads as
/// map_server reads it too. The arithmetic is map_io's, step by step in f64 (the mean of the
/// 16-bit quanta, divided by 65535, subtracted from 1): a pixel on a threshold rounds as
/// there, so a grey of 204 under `free_thresh: 0.2` is free here as on /map, not unknown.
fn map_server_value(pixel: Rgba<u16>, has_alpha: bool, spec: &MapSpec) -> i8 {
    const UNKNOWN: i8 = -1;
    let Rgba([r, g, b, a]) = pixel;
    let mut total = u32::from(r) + u32::from(g) + u32::from(b);
    let mut channels = 3;
    if spec.mode == MapMode::Trinary && has_alpha {
        total += u32::from(a);
        channels += 1;
    }
    let shade = f64::from(total) / f64::from(channels) / f64::from(u16::MAX);
    if spec.mode == MapMode::Raw {
        let value = (shade * 255.0).round();
        return if value <= 100.0 { value as i8 } else { UNKNOWN };
    }
    if spec.mode == MapMode::Scale && a != u16::MAX {
        return UNKNOWN;
    }
    let occupancy = if spec.negate { shade } else { 1.0 - shade };
    if occupancy > spec.occupied_thresh {
        100
    } else if occupancy < spec.free_thresh {
        0
    } else if spec.mode == MapMode::Scale {
        // Equal thresholds leave nothing in between but the threshold itself: free.
        let span = spec.occupied_thresh - spec.free_thresh;
        let fraction = if span > 0.0 {
            (occupancy - spec.free_thresh) / span
        } else {
            0.0
        };
        (fraction * 100.0).round_ties_even() as i8
    } else {
        UNKNOWN
    }
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

    /// The map of `yaml` (naming `image`) and the map read from `values` as /map is, with
    /// the same geometry, must have the same cells occupied and unknown.
    fn assert_loads_as_grid(yaml: &Path, values: &[i8]) {
        let map = load_map(yaml).unwrap();
        let geometry = *map.geometry();
        let (width, height) = (geometry.width, geometry.height);
        let grid =
            OccupancyMap::from_grid_values(geometry, values, MAP_SERVER_OCCUPIED_THRESH).unwrap();
        for (row, col) in (0..height).flat_map(|r| (0..width).map(move |c| (r, c))) {
            assert_eq!(
                (map.is_occupied(col, row), map.is_unknown(col, row)),
                (grid.is_occupied(col, row), grid.is_unknown(col, row)),
                "cell ({col}, {row}), published {}",
                values[row * width + col]
            );
        }
    }

    /// One row of grey pixels in scale and raw modes: the room is the one map_server would
    /// publish on /map from the same file. In scale mode a grey between the thresholds is
    /// scaled, not unknown (a floor drawn light grey had been unknown, behind the walls: the
    /// person was never seen with `--map`, and seen through the bag's /map).
    #[test]
    fn scale_and_raw_maps_load_as_map_server_publishes_them() {
        let dir = tempfile::tempdir().unwrap();
        let mut pgm = b"P5\n5 1\n255\n".to_vec();
        pgm.extend_from_slice(&[254, 185, 140, 100, 0]);
        write(dir.path(), "row.pgm", &pgm);
        let yaml = |mode: &str| {
            let text = format!(
                "image: row.pgm\nmode: {mode}\nresolution: 0.05\norigin: [0, 0, 0]\n\
                 negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.25\n"
            );
            write(dir.path(), &format!("{mode}.yaml"), text.as_bytes())
        };
        // Occupancy 0.004, 0.27, 0.45, 0.61, 1: scaled from (0.25, 0.65) to (0, 100).
        assert_loads_as_grid(&yaml("scale"), &[0, 6, 50, 89, 100]);
        let scale = load_map(&yaml("scale")).unwrap();
        assert!(!(0..5).any(|c| scale.is_unknown(c, 0)));
        assert!(scale.is_occupied(3, 0) && scale.is_occupied(4, 0));
        // Raw: the pixel values themselves, those above 100 unknown.
        assert_loads_as_grid(&yaml("raw"), &[-1, -1, -1, 100, 0]);
        // Trinary: between the thresholds unknown, as before.
        assert_loads_as_grid(&yaml("trinary"), &[0, -1, -1, -1, 100]);
    }

    /// A pixel whose occupancy is a threshold to the last digit falls on the side map_io's
    /// arithmetic puts it: 204 grey is 1 - 0.8 = 0.19999999999999996 there, under
    /// `free_thresh: 0.2`, so free; 0.2 computed in one division would make it unknown.
    #[test]
    fn a_pixel_on_a_threshold_falls_where_map_server_puts_it() {
        let dir = tempfile::tempdir().unwrap();
        let mut pgm = b"P5\n3 1\n255\n".to_vec();
        pgm.extend_from_slice(&[254, 204, 0]);
        write(dir.path(), "grey.pgm", &pgm);
        let yaml = write(
            dir.path(),
            "grey.yaml",
            b"image: grey.pgm\nmode: trinary\nresolution: 0.05\norigin: [0, 0, 0]\n\
              negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.2\n",
        );
        assert_loads_as_grid(&yaml, &[0, 0, 100]);
    }

    /// An RGBA PNG: map_server makes a pixel that is not opaque unknown in scale mode, and in
    /// trinary mode averages its opacity in with the colour channels.
    #[test]
    fn a_png_maps_transparency_is_read_as_map_server_reads_it() {
        let dir = tempfile::tempdir().unwrap();
        let pixels = [
            [254, 254, 254, 255],
            [185, 185, 185, 255],
            [200, 200, 200, 0],
        ];
        let png = image::RgbaImage::from_fn(3, 1, |x, _| Rgba(pixels[x as usize]));
        png.save(dir.path().join("row.png")).unwrap();
        let yaml = |mode: &str| {
            let text = format!(
                "image: row.png\nmode: {mode}\nresolution: 0.05\norigin: [0, 0, 0]\n\
                 negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.25\n"
            );
            write(dir.path(), &format!("{mode}.yaml"), text.as_bytes())
        };
        assert_loads_as_grid(&yaml("scale"), &[0, 6, -1]);
        // Opacity averaged in: 185 grey comes out lighter (occupancy 0.21: free), a
        // transparent 200 grey darker (0.41, between the thresholds: unknown).
        assert_loads_as_grid(&yaml("trinary"), &[0, 0, -1]);
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

    /// `yaml` naming `image` in `dir`, the rest of the file `extra` and the defaults.
    fn map_yaml(dir: &Path, name: &str, image: &str, extra: &str) -> PathBuf {
        let text = format!("image: {image}\nresolution: 0.5\norigin: [0, 0, 0]\n{extra}");
        write(dir, name, text.as_bytes())
    }

    /// Used to panic inside `image` ("Image index (0, 1) out of bounds (0, 2)").
    #[test]
    fn an_image_without_columns_is_refused_as_an_empty_map() {
        let dir = tempfile::tempdir().unwrap();
        for (name, header) in [("z02.pgm", "0 2"), ("z40.pgm", "4 0"), ("z00.pgm", "0 0")] {
            write(dir.path(), name, format!("P2\n{header}\n255\n").as_bytes());
            let yaml = map_yaml(dir.path(), &format!("{name}.yaml"), name, "");
            let err = load_map(&yaml).unwrap_err();
            assert!(
                matches!(
                    err,
                    FileError::Map {
                        cause: MapError::Empty { .. },
                        ..
                    }
                ),
                "{name}: {err}"
            );
        }
    }

    /// nav2 reads `negate` as a yaml-cpp int, else a yaml-cpp bool: `yes` and `"0"` used to
    /// fail here ("data did not match any variant of untagged enum Flag").
    #[test]
    fn negate_is_read_as_nav2_reads_it() {
        let dir = tempfile::tempdir().unwrap();
        write(dir.path(), "room.pgm", &pgm());
        let negated = |value: &str| {
            let yaml = map_yaml(
                dir.path(),
                "n.yaml",
                "room.pgm",
                &format!("negate: {value}\n"),
            );
            load_map(&yaml).map(|map| map.occupied_cells() == 11)
        };
        for value in [
            "1", "-1", "true", "True", "yes", "YES", "On", "y", "\"1\"", "'0x1'",
        ] {
            assert!(negated(value).unwrap(), "{value}");
        }
        for value in ["0", "false", "no", "No", "off", "N", "\"0\"", "'00'"] {
            assert!(!negated(value).unwrap(), "{value}");
        }
        let refused = [
            ("0.0", "0.0"),
            ("maybe", "maybe"),
            ("yEs", "yEs"),
            ("\"1.0\"", "'1.0'"),
            ("[0]", "a list"),
            ("~", "null"),
        ];
        for (value, given) in refused {
            let err = negated(value).unwrap_err().to_string();
            assert!(
                err.contains("negate must be an integer") && err.contains(&format!("not {given}")),
                "{value}: {err}"
            );
        }
    }

    /// nav2 ignores keys it does not know (forks add their own) and lowercases the mode.
    #[test]
    fn unknown_keys_are_ignored_and_the_mode_is_read_in_any_case() {
        let dir = tempfile::tempdir().unwrap();
        write(dir.path(), "room.pgm", &pgm());
        let extra = "name: room\nelevation_image: room_h.pgm\nmin_height: 0.1\nmode: Trinary\n";
        let map = load_map(&map_yaml(dir.path(), "a.yaml", "room.pgm", extra)).unwrap();
        assert_eq!((map.occupied_cells(), map.is_unknown(3, 0)), (1, true));
        let scale = load_map(&map_yaml(dir.path(), "b.yaml", "room.pgm", "mode: SCALE\n"));
        assert!(!scale.unwrap().is_unknown(3, 0));
        let err = load_map(&map_yaml(
            dir.path(),
            "c.yaml",
            "room.pgm",
            "mode: binary\n",
        ))
        .unwrap_err()
        .to_string();
        assert!(err.contains("trinary, scale or raw, not binary"), "{err}");
    }

    /// GraphicsMagick reads an image by its content: a PNG named `.pgm` and an image without
    /// an extension load; an empty `image` is refused as nav2 refuses it, naming the YAML.
    #[test]
    fn the_image_is_read_by_content_and_must_be_named() {
        let dir = tempfile::tempdir().unwrap();
        let png = image::GrayImage::from_fn(4, 3, |x, y| {
            image::Luma([if (x, y) == (0, 0) { 0 } else { 254 }])
        });
        png.save_with_format(dir.path().join("png.pgm"), image::ImageFormat::Png)
            .unwrap();
        png.save(dir.path().join("room.bmp")).unwrap();
        write(dir.path(), "room", &pgm());
        for image in ["png.pgm", "room", "room.bmp"] {
            let map = load_map(&map_yaml(dir.path(), "a.yaml", image, "")).unwrap();
            assert!(
                map.is_occupied(0, 2) && map.occupied_cells() == 1,
                "{image}"
            );
        }
        let err = load_map(&map_yaml(dir.path(), "empty.yaml", "\"\"", "")).unwrap_err();
        assert!(matches!(err, FileError::MapSpec { .. }), "{err}");
        let message = err.to_string();
        assert!(
            message.contains("empty.yaml") && message.contains("image tag is empty"),
            "{message}"
        );
    }

    /// A grey of 22938 / 65535 is occupancy 0.649989, not above 0.65: nav2 publishes it
    /// unknown. Cut to 8 bits it was 89 / 255 (0.651), occupied.
    #[test]
    fn sixteen_bit_images_are_thresholded_at_full_depth() {
        let dir = tempfile::tempdir().unwrap();
        let grey: u16 = 22938;
        let mut pgm = b"P5\n2 1\n65535\n".to_vec();
        for v in [grey, 0] {
            pgm.extend_from_slice(&v.to_be_bytes());
        }
        write(dir.path(), "g16.pgm", &pgm);
        image::ImageBuffer::<image::Luma<u16>, _>::from_vec(2, 1, vec![grey, 0])
            .unwrap()
            .save(dir.path().join("g16.png"))
            .unwrap();
        for image in ["g16.pgm", "g16.png"] {
            let yaml = map_yaml(dir.path(), &format!("{image}.yaml"), image, "");
            assert_loads_as_grid(&yaml, &[-1, 100]);
        }
        // Raw mode rounds the 16-bit shade on 0..=255 as nav2 does: 22938 / 257 = 89.25.
        write(
            dir.path(),
            "raw.pgm",
            &[b"P5\n1 1\n65535\n".as_slice(), &[0x59, 0xa0]].concat(),
        );
        let yaml = map_yaml(dir.path(), "raw.yaml", "raw.pgm", "mode: raw\n");
        assert_loads_as_grid(&yaml, &[89]);
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

    #[test]
    fn a_partial_mount_takes_the_default_mounts_other_fields() {
        // Used to fail with "mount: missing field `y`".
        let config = parse_localiser_config("mount: {x: 0.1}\n").unwrap();
        let default = LocaliserConfig::default().mount;
        assert_eq!(config.mount, Pose2::new(0.1, default.y, default.theta));
        let config = parse_localiser_config("mount:\n  theta: 1.5\n").unwrap();
        assert_eq!(config.mount, Pose2::new(default.x, default.y, 1.5));
        let err = parse_localiser_config("mount: {x: 0.1, z: 2}\n").unwrap_err();
        assert!(err.to_string().contains("unknown field `z`"), "{err}");
    }
}
