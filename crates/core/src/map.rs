//! The room's occupancy map with a precomputed distance field.
//!
//! The localiser asks, for every scan point, "is this within 0.2 m of a mapped obstacle?".
//! Computing the exact Euclidean distance transform once when the map is loaded (Felzenszwalb
//! and Huttenlocher's separable lower-envelope algorithm, linear in the number of cells) makes
//! each question one array read, whatever the map's size or clutter.

use glam::{DAffine2, DVec2};

use crate::geometry::Pose2;

/// Where the grid lies in the map frame and how fine it is, as in `nav_msgs/MapMetaData`:
/// cell `(col, row)` covers `[col, col+1) x [row, row+1)` times `resolution` in the grid frame,
/// whose origin (the corner of cell (0, 0)) sits at `origin` in the map frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapGeometry {
    pub resolution: f64,
    pub origin: Pose2,
    pub width: usize,
    pub height: usize,
}

/// Why a map cannot be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MapError {
    #[error("map resolution {0} m/cell is not a positive finite number")]
    Resolution(f64),
    #[error("map origin {0:?} is not finite")]
    Origin(Pose2),
    #[error("map is empty ({width} x {height} cells)")]
    Empty { width: usize, height: usize },
    #[error("map of {width} x {height} cells is larger than the {MAX_CELLS} cells supported")]
    TooLarge { width: usize, height: usize },
    #[error("map has {got} cells but width x height is {width} x {height} = {expected}")]
    CellCount {
        width: usize,
        height: usize,
        expected: usize,
        got: usize,
    },
    #[error("occupied threshold {0} is not in [0, 1]")]
    Threshold(f64),
}

/// 100 million cells (a 500 m square at 5 cm, far beyond any room the localiser watches).
/// Building a map takes about 11 bytes a cell at its peak (the grid values, the occupied and
/// unknown flags, the distances down one side and the distance field), plus buffers sized by
/// the length of a line (at most 800 kB, or an eighth of a byte a cell), whatever its shape,
/// so this bound keeps a load under about 1.1 GB: a larger map, or a garbled header, is an
/// error rather than the robot computer running out of memory.
pub const MAX_CELLS: usize = 100_000_000;

/// An occupancy grid reduced to what the localiser needs: which cells hold an obstacle and,
/// for every cell, the distance from its centre to the nearest obstacle cell's centre.
#[derive(Debug, Clone)]
pub struct OccupancyMap {
    geometry: MapGeometry,
    /// Map frame -> grid coordinates (in cells), precomputed so a lookup needs no `sin_cos`.
    map_to_grid: DAffine2,
    occupied: Vec<bool>,
    /// Cells whose state is unknown (outside the walls, never scanned); empty when all are known.
    unknown: Vec<bool>,
    /// Metres to the nearest occupied cell, row-major; `f32::INFINITY` when there is none.
    distance_m: Vec<f32>,
}

/// map_server's default threshold for an occupied cell (its `occupied_thresh`).
pub const MAP_SERVER_OCCUPIED_THRESH: f64 = 0.65;

impl OccupancyMap {
    /// Builds the map from one flag per cell (row-major, row 0 at the origin side).
    pub fn new(geometry: MapGeometry, occupied: Vec<bool>) -> Result<Self, MapError> {
        let MapGeometry {
            resolution,
            origin,
            width,
            height,
        } = geometry;
        if !(resolution.is_finite() && resolution > 0.0) {
            return Err(MapError::Resolution(resolution));
        }
        if !origin.is_finite() {
            return Err(MapError::Origin(origin));
        }
        if width == 0 || height == 0 {
            return Err(MapError::Empty { width, height });
        }
        let expected = width.checked_mul(height).filter(|&n| n <= MAX_CELLS);
        let Some(expected) = expected else {
            return Err(MapError::TooLarge { width, height });
        };
        if occupied.len() != expected {
            return Err(MapError::CellCount {
                width,
                height,
                expected,
                got: occupied.len(),
            });
        }
        let distance_m = distance_field(&occupied, width, height, resolution, STRIP_BLOCK_CELLS);
        let map_to_grid = DAffine2::from_scale(DVec2::splat(1.0 / resolution))
            * DAffine2::from_angle_translation(origin.theta, origin.position()).inverse();
        Ok(Self {
            geometry,
            map_to_grid,
            occupied,
            unknown: Vec::new(),
            distance_m,
        })
    }

    /// Like [`OccupancyMap::new`], with the cells whose state is unknown (same layout).
    pub fn with_unknown(
        geometry: MapGeometry,
        occupied: Vec<bool>,
        unknown: Vec<bool>,
    ) -> Result<Self, MapError> {
        if unknown.len() != occupied.len() {
            return Err(MapError::CellCount {
                width: geometry.width,
                height: geometry.height,
                expected: occupied.len(),
                got: unknown.len(),
            });
        }
        let mut map = Self::new(geometry, occupied)?;
        if unknown.contains(&true) {
            map.unknown = unknown;
        }
        Ok(map)
    }

    /// Builds the map from `nav_msgs/OccupancyGrid` values: 0..=100 is the occupancy
    /// probability in percent, -1 (or anything outside 0..=100) unknown. A cell is an obstacle
    /// when its probability exceeds `occupied_thresh` (map_server's meaning;
    /// [`MAP_SERVER_OCCUPIED_THRESH`] there); -1 is unknown.
    pub fn from_grid_values(
        geometry: MapGeometry,
        values: &[i8],
        occupied_thresh: f64,
    ) -> Result<Self, MapError> {
        if !(0.0..=1.0).contains(&occupied_thresh) {
            return Err(MapError::Threshold(occupied_thresh));
        }
        let limit = occupied_thresh * 100.0;
        let occupied = values
            .iter()
            .map(|&v| (0..=100).contains(&v) && f64::from(v) > limit)
            .collect();
        let unknown = values.iter().map(|v| !(0..=100).contains(v)).collect();
        Self::with_unknown(geometry, occupied, unknown)
    }

    pub fn geometry(&self) -> &MapGeometry {
        &self.geometry
    }

    pub fn occupied_cells(&self) -> usize {
        self.occupied.iter().filter(|&&o| o).count()
    }

    /// The `(col, row)` of the cell holding map-frame point `p`, if it is on the map.
    pub fn cell_of(&self, p: DVec2) -> Option<(usize, usize)> {
        let g = self.map_to_grid.transform_point2(p);
        // Also false for NaN, so a bad point never indexes the grid.
        let inside = g.x >= 0.0
            && g.y >= 0.0
            && g.x < self.geometry.width as f64
            && g.y < self.geometry.height as f64;
        inside.then_some((g.x as usize, g.y as usize))
    }

    pub fn is_occupied(&self, col: usize, row: usize) -> bool {
        col < self.geometry.width
            && row < self.geometry.height
            && self.occupied[row * self.geometry.width + col]
    }

    /// Whether the cell `(col, row)` is of unknown state (false off the map).
    pub fn is_unknown(&self, col: usize, row: usize) -> bool {
        col < self.geometry.width
            && row < self.geometry.height
            && self.unknown.get(row * self.geometry.width + col) == Some(&true)
    }

    /// Metres from the cell holding `p` to the nearest obstacle when that cell is known to be
    /// free; `None` when `p` is off the map, in an unknown cell or in an obstacle.
    pub fn free_clearance(&self, p: DVec2) -> Option<f32> {
        let (col, row) = self.cell_of(p)?;
        let i = row * self.geometry.width + col;
        if self.occupied[i] || self.unknown.get(i) == Some(&true) {
            return None;
        }
        Some(self.distance_m[i])
    }

    /// Metres from the cell holding `p` to the nearest obstacle (`INFINITY` on a map without
    /// obstacles), or `None` when `p` is off the map. Accurate to half a cell diagonal.
    pub fn distance_to_obstacle(&self, p: DVec2) -> Option<f32> {
        self.cell_of(p)
            .map(|(col, row)| self.distance_m[row * self.geometry.width + col])
    }
}

/// Metres from every cell to the nearest `true` cell (row-major, `INFINITY` where there is
/// none): the distance down every column in whole cells, then the exact lower envelope of
/// their squares along every row; for a strip (wider than tall, under [`STRIP_ROWS`] rows)
/// the other way round, along the rows and then down the columns. The first distances are
/// kept as `u32` rather than squared distances as `f64`, and each line of the envelope goes
/// straight into the `f32` field: a map of 10000 x 10000 cells took 1.57 GB to build with a
/// whole `f64` grid. The envelope's buffers (32 bytes a cell of its line) are then at most
/// 320 kB (rows of a map at least as tall as wide: 10,000 cells), an eighth of a byte a cell
/// (rows of a wide map of at least `STRIP_ROWS` rows), or 800 kB (a strip's columns, 65,536
/// cells at a time): sized by the width whatever the shape, a strip of 25,000,000 x 1 cells had taken
/// 800 MB of them on top of its 200 MB field.
///
/// The result is the same to the bit as the brute force's: the squares are integers, exact
/// in `f64` below 2^53. Along an envelope line every index is under 400,000 (100 million
/// cells over 256 rows); the first distances are under `MAX_CELLS / 2` when both
/// sides are at least two cells, so their squares stay under 2^53; with one side of one
/// cell, the envelope of a single cell is its own square, whose `sqrt` rounds back to the
/// integer distance (under 2^27).
///
/// A strip's columns go through the envelope `block_cells / height` at a time (at least one):
/// [`STRIP_BLOCK_CELLS`] but in tests, which set it small to take many blocks.
fn distance_field(
    occupied: &[bool],
    width: usize,
    height: usize,
    resolution: f64,
    block_cells: usize,
) -> Vec<f32> {
    // No real distance gets near it: a line has at most MAX_CELLS cells.
    const NONE: u32 = u32::MAX;
    let n = occupied.len();
    let mut along = vec![NONE; n];
    let strip = width > height && height < STRIP_ROWS;
    // The envelope's lines: rows of `len` cells, or a strip's columns.
    let len;
    if !strip {
        // Down every column, then along the rows.
        for i in 0..n {
            if occupied[i] {
                along[i] = 0;
            } else if i >= width {
                along[i] = along[i - width].saturating_add(1);
            }
        }
        for i in (0..n - width).rev() {
            along[i] = along[i].min(along[i + width].saturating_add(1));
        }
        len = width;
    } else {
        // Along every row, then down the columns.
        for (row, cells) in along
            .chunks_exact_mut(width)
            .zip(occupied.chunks_exact(width))
        {
            for c in 0..width {
                if cells[c] {
                    row[c] = 0;
                } else if c > 0 {
                    row[c] = row[c - 1].saturating_add(1);
                }
            }
            for c in (0..width - 1).rev() {
                row[c] = row[c].min(row[c + 1].saturating_add(1));
            }
        }
        len = height;
    }
    let square = |cells: u32| {
        if cells == NONE {
            f64::INFINITY
        } else {
            f64::from(cells) * f64::from(cells)
        }
    };
    let metres = |d2: f64| (d2.sqrt() * resolution) as f32;
    let mut scratch = EnvelopeScratch::new(len);
    let mut out = vec![0.0; len];
    let mut distance_m = vec![0.0f32; n];
    if !strip {
        let mut line = vec![0.0; len];
        for (row, field) in along
            .chunks_exact(width)
            .zip(distance_m.chunks_exact_mut(width))
        {
            for (f, &cells) in line.iter_mut().zip(row) {
                *f = square(cells);
            }
            scratch.transform(&line, &mut out);
            for (d, &d2) in field.iter_mut().zip(&out) {
                *d = metres(d2);
            }
        }
    } else {
        // The columns, a block of about `block_cells` cells at a time, gathered and scattered
        // a row at a time: row by row, each block's columns are one run of memory.
        let block = (block_cells / len).max(1);
        let mut lines = vec![0.0; block * len];
        let mut fields = vec![0.0f32; block * len];
        for first in (0..width).step_by(block) {
            let columns = first..(first + block).min(width);
            for (r, row) in along.chunks_exact(width).enumerate() {
                for (i, &cells) in row[columns.clone()].iter().enumerate() {
                    lines[i * len + r] = square(cells);
                }
            }
            for i in 0..columns.len() {
                scratch.transform(&lines[i * len..(i + 1) * len], &mut out);
                for (d, &d2) in fields[i * len..(i + 1) * len].iter_mut().zip(&out) {
                    *d = metres(d2);
                }
            }
            for (r, row) in distance_m.chunks_exact_mut(width).enumerate() {
                for (i, d) in row[columns.clone()].iter_mut().enumerate() {
                    *d = fields[i * len + r];
                }
            }
        }
    }
    distance_m
}

/// Maps wider than tall with fewer rows than this are strips: their distance transform runs
/// its envelope down the columns. Along the rows its buffers would take 32 bytes a cell of
/// width, more than the map itself (a strip of 25,000,000 x 1 cells: 800 MB); down the
/// columns of a map thousands of rows tall, every cell misses the cache (a 20000 x 5000 map
/// loaded in 2.5 s instead of 1.4 s).
const STRIP_ROWS: usize = 256;

/// A strip's columns go through the envelope in blocks of about this many cells (512 KB of
/// `f64` lines), gathered from and scattered to the rows a block at a time.
const STRIP_BLOCK_CELLS: usize = 1 << 16;

/// Buffers of the lower envelope of parabolas, reused across lines.
struct EnvelopeScratch {
    /// Positions of the parabolas in the envelope.
    apex: Vec<usize>,
    /// Boundaries between consecutive envelope parabolas.
    bound: Vec<f64>,
}

impl EnvelopeScratch {
    fn new(n: usize) -> Self {
        Self {
            apex: vec![0; n],
            bound: vec![0.0; n + 1],
        }
    }

    /// Where the parabola at `q` (with `fq = f[q] + q^2`) overtakes envelope parabola `k`.
    fn intersection(&self, f: &[f64], fq: f64, q: usize, k: usize) -> f64 {
        let p = self.apex[k];
        (fq - (f[p] + (p * p) as f64)) / (2.0 * (q - p) as f64)
    }

    /// `out[q] = min_p (q - p)^2 + f[p]` over the finite `f[p]`; infinite where none is finite.
    fn transform(&mut self, f: &[f64], out: &mut [f64]) {
        let mut k: usize = 0;
        let mut any = false;
        for q in 0..f.len() {
            if !f[q].is_finite() {
                continue;
            }
            if !any {
                any = true;
                self.apex[0] = q;
                self.bound[0] = f64::NEG_INFINITY;
                self.bound[1] = f64::INFINITY;
                continue;
            }
            let fq = f[q] + (q * q) as f64;
            // `bound[0]` is -inf, so the envelope never empties.
            let mut s = self.intersection(f, fq, q, k);
            while s <= self.bound[k] {
                k -= 1;
                s = self.intersection(f, fq, q, k);
            }
            k += 1;
            self.apex[k] = q;
            self.bound[k] = s;
            self.bound[k + 1] = f64::INFINITY;
        }
        if !any {
            out.fill(f64::INFINITY);
            return;
        }
        let mut k = 0;
        for (q, o) in out.iter_mut().enumerate() {
            while self.bound[k + 1] < q as f64 {
                k += 1;
            }
            let p = self.apex[k];
            let d = q as f64 - p as f64;
            *o = d * d + f[p];
        }
    }
}

/// The test binary's allocator counts the bytes each thread has live and the most it had,
/// so a test can measure the peak memory of what it runs (tests run on their own threads).
#[cfg(test)]
mod peak_memory {
    use std::alloc::{GlobalAlloc, Layout, System};
    use std::cell::Cell;

    thread_local! {
        static LIVE: Cell<usize> = const { Cell::new(0) };
        static PEAK: Cell<usize> = const { Cell::new(0) };
    }

    pub struct Counting;

    fn grow(bytes: usize) {
        let live = LIVE.get() + bytes;
        LIVE.set(live);
        PEAK.set(PEAK.get().max(live));
    }

    fn shrink(bytes: usize) {
        // Memory allocated on another thread may be freed on this one.
        LIVE.set(LIVE.get().saturating_sub(bytes));
    }

    // SAFETY: every call is forwarded to `System` unchanged; the counting touches only
    // const-initialised thread-locals without destructors, which never allocate.
    unsafe impl GlobalAlloc for Counting {
        unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
            let ptr = unsafe { System.alloc(layout) };
            if !ptr.is_null() {
                grow(layout.size());
            }
            ptr
        }

        unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
            let ptr = unsafe { System.alloc_zeroed(layout) };
            if !ptr.is_null() {
                grow(layout.size());
            }
            ptr
        }

        unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
            unsafe { System.dealloc(ptr, layout) };
            shrink(layout.size());
        }

        unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
            let moved = unsafe { System.realloc(ptr, layout, new_size) };
            if !moved.is_null() {
                shrink(layout.size());
                grow(new_size);
            }
            moved
        }
    }

    #[global_allocator]
    static ALLOCATOR: Counting = Counting;

    /// What `f` returns, and the most bytes it had allocated at once on this thread.
    pub fn peak_during<T>(f: impl FnOnce() -> T) -> (T, usize) {
        let base = LIVE.get();
        PEAK.set(base);
        let value = f();
        (value, PEAK.get() - base)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn geometry(width: usize, height: usize, resolution: f64) -> MapGeometry {
        MapGeometry {
            resolution,
            origin: Pose2::IDENTITY,
            width,
            height,
        }
    }

    fn brute_force(occupied: &[bool], width: usize, height: usize) -> Vec<f64> {
        let cells: Vec<(i64, i64)> = (0..occupied.len())
            .filter(|&i| occupied[i])
            .map(|i| ((i % width) as i64, (i / width) as i64))
            .collect();
        (0..width * height)
            .map(|i| {
                let (c, r) = ((i % width) as i64, (i / width) as i64);
                cells
                    .iter()
                    .map(|&(oc, or)| ((oc - c).pow(2) + (or - r).pow(2)) as f64)
                    .fold(f64::INFINITY, f64::min)
            })
            .collect()
    }

    proptest! {
        #[test]
        fn distance_transform_is_exact(
            // Wider than tall makes a strip, whose columns go through the envelope in blocks
            // of `block_cells / height` (the production blocks never split a map this small).
            width in 1usize..40,
            height in 1usize..14,
            block_cells in 1usize..64,
            seed in proptest::collection::vec(any::<bool>(), 40 * 14),
            density in 1u8..8,
            resolution in 0.01f64..1.0,
        ) {
            let occupied: Vec<bool> = (0..width * height)
                .map(|i| seed[i] && (i as u8).is_multiple_of(density))
                .collect();
            let fast = distance_field(&occupied, width, height, resolution, block_cells);
            let slow: Vec<f32> = brute_force(&occupied, width, height)
                .iter()
                .map(|&d2| (d2.sqrt() * resolution) as f32)
                .collect();
            prop_assert_eq!(fast, slow);
        }
    }

    #[test]
    fn a_strip_in_many_blocks_matches_the_plain_path() {
        // The strip path, in blocks of a few columns (the last one short), against the plain
        // path (rows, then columns) on the transposed map: the same distances to the bit.
        for (width, height, block_cells) in [
            (70_000, 2, 999),
            (5_000, 255, 255 * 7),
            (3_000, 30, 30 * 11 + 29),
        ] {
            let occupied: Vec<bool> = (0..width * height).map(|i| (i * 7919) % 1009 < 3).collect();
            let strip = distance_field(&occupied, width, height, 0.05, block_cells);
            let transposed: Vec<bool> = (0..width * height)
                .map(|i| occupied[(i % height) * width + i / height])
                .collect();
            let plain = distance_field(&transposed, height, width, 0.05, block_cells);
            for (i, &d) in strip.iter().enumerate() {
                let (c, r) = (i % width, i / width);
                assert_eq!(
                    d.to_bits(),
                    plain[c * height + r].to_bits(),
                    "{width} x {height}: cell {c}, {r}"
                );
            }
            assert!(strip.iter().any(|d| d.is_finite() && *d > 0.0));
        }
    }

    #[test]
    fn building_the_field_takes_8_bytes_a_cell_whatever_the_shape() {
        // The distances along one side (u32) and the field (f32); the envelope's buffers are
        // sized by the shorter side. Sized by the width, a strip of 25,000,000 x 1 cells had
        // taken 613 MB to load: 32 bytes a cell of width on top.
        let shapes = [
            (1_000_000, 2),
            (2, 1_000_000),
            (1_000_000, 1),
            (1000, 1000),
            (5_000, 255),
            (5_000, 256),
        ];
        for (width, height) in shapes {
            let occupied: Vec<bool> = (0..width * height).map(|i| i % 997 == 0).collect();
            let (field, peak) = super::peak_memory::peak_during(|| {
                distance_field(&occupied, width, height, 0.05, STRIP_BLOCK_CELLS)
            });
            assert_eq!(field.len(), width * height);
            let bound = 8 * width * height + width * height / 8 + 1_000_000;
            assert!(
                peak <= bound,
                "{width} x {height}: {peak} bytes at the peak, more than {bound}"
            );
        }
    }

    #[test]
    fn distance_is_measured_in_metres_from_the_point_cell() {
        // A wall along column 10 of a 5 cm map: 2 m wide, 1 m tall.
        let (w, h) = (40, 20);
        let occupied = (0..w * h).map(|i| i % w == 10).collect();
        let map = OccupancyMap::new(geometry(w, h, 0.05), occupied).unwrap();
        let d = map
            .distance_to_obstacle(DVec2::new(0.5 + 0.025, 0.3))
            .unwrap();
        assert!(d.abs() < 1e-6, "on the wall: {d}");
        let d = map
            .distance_to_obstacle(DVec2::new(0.8 + 0.025, 0.3))
            .unwrap();
        assert!((d - 0.3).abs() < 1e-5, "6 cells away: {d}");
        assert!(map.distance_to_obstacle(DVec2::new(-0.01, 0.3)).is_none());
        assert!(
            map.distance_to_obstacle(DVec2::new(f64::NAN, 0.3))
                .is_none()
        );
        assert_eq!(map.occupied_cells(), 20);
    }

    #[test]
    fn rotated_origin_is_honoured() {
        // Grid rotated by 90 degrees: grid +x is map +y; origin at (1, 1).
        let origin = Pose2::new(1.0, 1.0, std::f64::consts::FRAC_PI_2);
        let g = MapGeometry {
            resolution: 0.1,
            origin,
            width: 10,
            height: 10,
        };
        let mut occupied = vec![false; 100];
        occupied[3 * 10 + 2] = true; // col 2, row 3: grid (0.25, 0.35) -> map (1 - 0.35, 1 + 0.25)
        let map = OccupancyMap::new(g, occupied).unwrap();
        assert_eq!(map.cell_of(DVec2::new(0.65, 1.25)), Some((2, 3)));
        assert_eq!(map.distance_to_obstacle(DVec2::new(0.65, 1.25)), Some(0.0));
    }

    #[test]
    fn map_without_obstacles_is_infinitely_far() {
        let map = OccupancyMap::new(geometry(3, 3, 1.0), vec![false; 9]).unwrap();
        assert_eq!(
            map.distance_to_obstacle(DVec2::new(1.5, 1.5)),
            Some(f32::INFINITY)
        );
    }

    #[test]
    fn grid_values_follow_map_server_thresholds() {
        let values = [0i8, 50, 65, 66, 100, -1, 127, -128, 99];
        let map = OccupancyMap::from_grid_values(geometry(9, 1, 1.0), &values, 0.65).unwrap();
        let occ: Vec<bool> = (0..9).map(|c| map.is_occupied(c, 0)).collect();
        assert_eq!(
            occ,
            [false, false, false, true, true, false, false, false, true]
        );
        let unknown: Vec<bool> = (0..9).map(|c| map.is_unknown(c, 0)).collect();
        assert_eq!(
            unknown,
            [false, false, false, false, false, true, true, true, false]
        );
        // Only known free cells have a clearance; occupied, unknown and off-map have none.
        let at = |x: f64| map.free_clearance(DVec2::new(x, 0.5));
        assert_eq!(at(0.5), Some(3.0));
        assert_eq!(at(2.5), Some(1.0));
        assert_eq!((at(3.5), at(5.5), at(-0.5)), (None, None, None));
        assert_eq!(map.distance_to_obstacle(DVec2::new(5.5, 0.5)), Some(1.0));
    }

    #[test]
    fn unknown_flags_must_match_the_grid() {
        assert!(matches!(
            OccupancyMap::with_unknown(geometry(2, 2, 0.1), vec![false; 4], vec![true; 3]),
            Err(MapError::CellCount {
                expected: 4,
                got: 3,
                ..
            })
        ));
        let all_known =
            OccupancyMap::with_unknown(geometry(2, 1, 1.0), vec![true, false], vec![false; 2])
                .unwrap();
        assert_eq!(all_known.free_clearance(DVec2::new(1.5, 0.5)), Some(1.0));
    }

    #[test]
    fn bad_maps_are_rejected_with_the_reason() {
        assert_eq!(
            OccupancyMap::new(geometry(2, 2, 0.0), vec![false; 4]).unwrap_err(),
            MapError::Resolution(0.0)
        );
        assert!(matches!(
            OccupancyMap::new(geometry(2, 2, f64::NAN), vec![false; 4]),
            Err(MapError::Resolution(_))
        ));
        assert!(matches!(
            OccupancyMap::new(geometry(2, 2, 0.1), vec![false; 3]),
            Err(MapError::CellCount {
                expected: 4,
                got: 3,
                ..
            })
        ));
        assert!(matches!(
            OccupancyMap::new(geometry(0, 2, 0.1), vec![]),
            Err(MapError::Empty { .. })
        ));
        assert!(matches!(
            OccupancyMap::new(geometry(usize::MAX, 2, 0.1), vec![]),
            Err(MapError::TooLarge { .. })
        ));
        // Within the old bound of 400 million cells, which took 6.4 GB to load.
        let err = OccupancyMap::new(geometry(20_000, 10_000, 0.05), vec![]).unwrap_err();
        assert!(matches!(err, MapError::TooLarge { .. }), "{err}");
        let message = err.to_string();
        assert!(
            message.contains("20000 x 10000") && message.contains("100000000"),
            "{message}"
        );
        let mut g = geometry(1, 1, 0.1);
        g.origin.theta = f64::INFINITY;
        assert!(matches!(
            OccupancyMap::new(g, vec![true]),
            Err(MapError::Origin(_))
        ));
        assert!(matches!(
            OccupancyMap::from_grid_values(geometry(1, 1, 0.1), &[0], 1.5),
            Err(MapError::Threshold(_))
        ));
    }
}
