//! The room map as the Lidar sees it (walls and furniture cut at the Lidar's height), as an
//! occupancy grid and in map_server's PGM + YAML format.

use std::io::Write;
use std::path::{Path, PathBuf};

use glam::DVec2;
use lidar_har_core::geometry::Pose2;
use lidar_har_core::map::{MAP_SERVER_OCCUPIED_THRESH, MapError, MapGeometry};

use crate::shapes::{point_in_polygon, point_segment_dist};
use crate::world::World;

/// Default map resolution, metres per cell.
pub const DEFAULT_RESOLUTION: f64 = 0.05;
/// Margin of unknown cells around the room's bounds.
const BORDER: f64 = 0.5;

pub const OCCUPIED: i8 = 100;
pub const FREE: i8 = 0;
pub const UNKNOWN: i8 = -1;

/// An occupancy grid in ROS's layout: row-major from the origin (lower-left) corner,
/// 100 occupied, 0 free, -1 unknown (outside the room).
#[derive(Debug, Clone, PartialEq)]
pub struct OccupancyMap {
    pub resolution: f64,
    /// Map-frame position of the lower-left corner of cell (0, 0).
    pub origin: DVec2,
    pub width: u32,
    pub height: u32,
    pub data: Vec<i8>,
}

impl OccupancyMap {
    /// The grid as the localiser's map, read as /map is (map_server's default threshold).
    pub fn to_localiser_map(&self) -> Result<lidar_har_core::map::OccupancyMap, MapError> {
        let geometry = MapGeometry {
            resolution: self.resolution,
            origin: Pose2::new(self.origin.x, self.origin.y, 0.0),
            width: self.width as usize,
            height: self.height as usize,
        };
        lidar_har_core::map::OccupancyMap::from_grid_values(
            geometry,
            &self.data,
            MAP_SERVER_OCCUPIED_THRESH,
        )
    }

    /// Rasterises what the Lidar plane cuts: a cell is occupied when a wall or furniture
    /// edge passes within half a cell of its centre or its centre lies inside furniture.
    pub fn from_world(world: &World, resolution: f64) -> Self {
        let (lo, hi) = world.bounds();
        let origin = lo - DVec2::splat(BORDER);
        let width = (((hi.x - lo.x + 2.0 * BORDER) / resolution).ceil() as u32).max(1);
        let height = (((hi.y - lo.y + 2.0 * BORDER) / resolution).ceil() as u32).max(1);
        // Half a cell, plus a hair so an edge exactly on a cell border marks that cell.
        let half = resolution / 2.0 + 1e-9;
        let mut data = vec![UNKNOWN; width as usize * height as usize];
        // Furniture solids cut by the plane (edges come with the segments).
        let seen_solids: Vec<&Vec<DVec2>> = world
            .furniture
            .iter()
            .filter(|f| f.height > world.lidar_height)
            .flat_map(|f| f.robot_blocks.iter())
            .filter_map(|s| match s {
                crate::shapes::Shape::Polygon(p) => Some(p),
                crate::shapes::Shape::Circle { .. } => None,
            })
            .collect();
        for j in 0..height {
            for i in 0..width {
                let c = origin
                    + DVec2::new((i as f64 + 0.5) * resolution, (j as f64 + 0.5) * resolution);
                let near_edge = world
                    .segments
                    .iter()
                    .any(|s| point_segment_dist(c, s.a, s.b) <= half);
                let in_circle = world
                    .circles
                    .iter()
                    .any(|k| (c - k.center).length() <= k.radius + half);
                let in_solid = seen_solids.iter().any(|p| point_in_polygon(c, p));
                let value = if near_edge || in_circle || in_solid {
                    OCCUPIED
                } else if point_in_polygon(c, &world.outline) {
                    FREE
                } else {
                    UNKNOWN
                };
                data[(j * width + i) as usize] = value;
            }
        }
        Self {
            resolution,
            origin,
            width,
            height,
            data,
        }
    }

    /// Writes `<dir>/<stem>.pgm` and `<dir>/<stem>.yaml` as map_server reads them
    /// (trinary: 0 black occupied, 254 white free, 205 grey unknown; top row first).
    /// `free_thresh` is map_saver's 0.196, just below 205's occupancy (50/255): with a higher
    /// one the grey reads as free and the unknown cells of /map become floor.
    /// Both files are created new, so a map already there (or one another process writes
    /// meanwhile) is never clobbered.
    pub fn write_map_server(&self, dir: &Path, stem: &str) -> std::io::Result<()> {
        let [pgm_path, yaml_path] = map_server_files(dir, stem);
        let mut out = std::io::BufWriter::new(create_new(&pgm_path)?);
        let mut yaml_file = create_new(&yaml_path).inspect_err(|_| {
            // The PGM is ours and empty: leave nothing half-written behind.
            let _ = std::fs::remove_file(&pgm_path);
        })?;
        write!(
            out,
            "P5\n# lidar_har simulator map\n{} {}\n255\n",
            self.width, self.height
        )?;
        for j in (0..self.height).rev() {
            let row: Vec<u8> = (0..self.width)
                .map(|i| match self.data[(j * self.width + i) as usize] {
                    OCCUPIED => 0,
                    FREE => 254,
                    _ => 205,
                })
                .collect();
            out.write_all(&row)?;
        }
        out.flush()?;
        let yaml = format!(
            "image: {stem}.pgm\nmode: trinary\nresolution: {}\norigin: [{}, {}, 0.0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n",
            self.resolution, self.origin.x, self.origin.y
        );
        yaml_file.write_all(yaml.as_bytes())
    }
}

/// The two files `write_map_server` writes: `<dir>/<stem>.pgm` and `<dir>/<stem>.yaml`.
fn map_server_files(dir: &Path, stem: &str) -> [PathBuf; 2] {
    [
        dir.join(format!("{stem}.pgm")),
        dir.join(format!("{stem}.yaml")),
    ]
}

/// Fails naming the first of `write_map_server`'s files already in `dir`, so that a caller
/// can refuse before it writes anything else there.
pub fn check_map_server_free(dir: &Path, stem: &str) -> std::io::Result<()> {
    match map_server_files(dir, stem).into_iter().find(|p| p.exists()) {
        Some(p) => Err(already_exists(&p)),
        None => Ok(()),
    }
}

fn already_exists(path: &Path) -> std::io::Error {
    std::io::Error::new(
        std::io::ErrorKind::AlreadyExists,
        format!("{} already exists", path.display()),
    )
}

fn create_new(path: &Path) -> std::io::Result<std::fs::File> {
    std::fs::File::create_new(path).map_err(|e| match e.kind() {
        std::io::ErrorKind::AlreadyExists => already_exists(path),
        _ => e,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;

    #[test]
    fn square_room_with_table_legs() {
        let text = "duration: 1\nroom: {outline: [[0,0],[4,0],[4,3],[0,3]]}\nfurniture: [{kind: table, center: [2, 1.5], size: [1, 1], height: 0.7}]\nrobot: {start: {x: 0.5, y: 0.5}}\n";
        let s = Scene::parse(text, "t").unwrap();
        let m = OccupancyMap::from_world(&World::new(&s), 0.05);
        let at = |x: f64, y: f64| {
            let i = ((x - m.origin.x) / m.resolution) as u32;
            let j = ((y - m.origin.y) / m.resolution) as u32;
            m.data[(j * m.width + i) as usize]
        };
        assert_eq!(at(1.0, 1.0), FREE);
        assert_eq!(at(0.01, 1.0), OCCUPIED, "wall");
        assert_eq!(at(-0.3, 1.0), UNKNOWN, "outside");
        assert_eq!(at(2.0, 1.5), FREE, "under the table top");
        assert_eq!(at(1.55, 1.05), OCCUPIED, "a leg");
        let dir = tempfile::tempdir().unwrap();
        m.write_map_server(dir.path(), "map").unwrap();
        let pgm = std::fs::read(dir.path().join("map.pgm")).unwrap();
        let header = format!(
            "P5\n# lidar_har simulator map\n{} {}\n255\n",
            m.width, m.height
        );
        assert_eq!(pgm.len(), header.len() + (m.width * m.height) as usize);
        let yaml = std::fs::read(dir.path().join("map.yaml")).unwrap();
        let err = m.write_map_server(dir.path(), "map").unwrap_err();
        assert_eq!(err.kind(), std::io::ErrorKind::AlreadyExists);
        let want = format!("{} already exists", dir.path().join("map.pgm").display());
        assert_eq!(err.to_string(), want);
        assert_eq!(std::fs::read(dir.path().join("map.pgm")).unwrap(), pgm);
        assert_eq!(std::fs::read(dir.path().join("map.yaml")).unwrap(), yaml);
        // A YAML alone is kept too, and no PGM is left beside it.
        std::fs::remove_file(dir.path().join("map.pgm")).unwrap();
        std::fs::write(dir.path().join("map.yaml"), "mine").unwrap();
        assert!(m.write_map_server(dir.path(), "map").is_err());
        assert!(!dir.path().join("map.pgm").exists());
        assert_eq!(std::fs::read(dir.path().join("map.yaml")).unwrap(), b"mine");
    }
}
