//! Grouping foreground points into objects.
//!
//! Single-linkage clustering with a distance tolerance (DBSCAN with one point per core), done
//! in two cheap steps that exploit the scan order: consecutive foreground points closer than
//! the tolerance form segments in one pass, then segments are joined when any of their points
//! are closer than the tolerance (checked only for segments whose boxes overlap). The second
//! step joins the two legs of a person that a background surface splits in beam order, and
//! the first and last beams of a 360-degree scan.

use glam::DVec2;
use serde::{Deserialize, Serialize};

/// Clustering parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ClusterConfig {
    /// Points closer than this (metres) belong to the same object.
    pub tolerance_m: f64,
    /// Clusters with fewer points are noise (stray and multipath returns).
    pub min_points: usize,
    /// Clusters whose bounding box diagonal exceeds this (metres) are not a person: a person
    /// lying down is under 2 m long.
    pub max_extent_m: f64,
}

impl Default for ClusterConfig {
    fn default() -> Self {
        Self {
            tolerance_m: 0.35,
            min_points: 3,
            max_extent_m: 2.2,
        }
    }
}

/// An object seen in one scan.
#[derive(Debug, Clone, PartialEq)]
pub struct Cluster {
    pub centroid: DVec2,
    pub points: Vec<DVec2>,
    /// Bounding box diagonal, metres.
    pub extent_m: f64,
}

/// A consecutive run `points[start..end]` and its bounding box.
#[derive(Debug, Clone, Copy)]
struct Segment {
    start: usize,
    end: usize,
    min: DVec2,
    max: DVec2,
}

/// Reusable clustering buffers, so a scan allocates only the clusters it returns.
#[derive(Debug, Default)]
pub struct Clusterer {
    segments: Vec<Segment>,
    parent: Vec<usize>,
}

impl Clusterer {
    /// Clusters `points` (foreground points in beam order, all finite) into `out`, keeping
    /// only clusters that can be a person.
    pub fn cluster(&mut self, points: &[DVec2], config: &ClusterConfig, out: &mut Vec<Cluster>) {
        out.clear();
        let tol = config.tolerance_m;
        let tol2 = tol * tol;
        self.segments.clear();
        for (i, &p) in points.iter().enumerate() {
            match self.segments.last_mut() {
                Some(seg) if points[seg.end - 1].distance_squared(p) <= tol2 => {
                    seg.end = i + 1;
                    seg.min = seg.min.min(p);
                    seg.max = seg.max.max(p);
                }
                _ => self.segments.push(Segment {
                    start: i,
                    end: i + 1,
                    min: p,
                    max: p,
                }),
            }
        }
        let n = self.segments.len();
        self.parent.clear();
        self.parent.extend(0..n);
        for a in 0..n {
            for b in a + 1..n {
                let (sa, sb) = (self.segments[a], self.segments[b]);
                let boxes_touch = sa.min.x - tol <= sb.max.x
                    && sb.min.x - tol <= sa.max.x
                    && sa.min.y - tol <= sb.max.y
                    && sb.min.y - tol <= sa.max.y;
                if boxes_touch
                    && find(&mut self.parent, a) != find(&mut self.parent, b)
                    && segments_touch(&points[sa.start..sa.end], &points[sb.start..sb.end], tol2)
                {
                    let (ra, rb) = (find(&mut self.parent, a), find(&mut self.parent, b));
                    self.parent[rb] = ra;
                }
            }
        }
        for root in 0..n {
            if find(&mut self.parent, root) != root {
                continue;
            }
            let mut cluster_points = Vec::new();
            let (mut min, mut max) = (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
            for s in 0..n {
                if find(&mut self.parent, s) == root {
                    let seg = self.segments[s];
                    cluster_points.extend_from_slice(&points[seg.start..seg.end]);
                    min = min.min(seg.min);
                    max = max.max(seg.max);
                }
            }
            let extent_m = (max - min).length();
            if cluster_points.len() < config.min_points || extent_m > config.max_extent_m {
                continue;
            }
            let centroid =
                cluster_points.iter().copied().sum::<DVec2>() / cluster_points.len() as f64;
            out.push(Cluster {
                centroid,
                points: cluster_points,
                extent_m,
            });
        }
    }
}

fn segments_touch(a: &[DVec2], b: &[DVec2], tol2: f64) -> bool {
    a.iter()
        .any(|p| b.iter().any(|q| p.distance_squared(*q) <= tol2))
}

fn find(parent: &mut [usize], mut i: usize) -> usize {
    while parent[i] != i {
        parent[i] = parent[parent[i]];
        i = parent[i];
    }
    i
}

#[cfg(test)]
mod tests {
    use super::*;

    fn arc(center: DVec2, radius: f64, n: usize) -> Vec<DVec2> {
        (0..n)
            .map(|i| {
                center + radius * DVec2::from_angle(std::f64::consts::PI * i as f64 / n as f64)
            })
            .collect()
    }

    fn run(points: &[DVec2]) -> Vec<Cluster> {
        let mut out = Vec::new();
        Clusterer::default().cluster(points, &ClusterConfig::default(), &mut out);
        out
    }

    #[test]
    fn two_legs_split_in_beam_order_form_one_person() {
        let left = arc(DVec2::new(2.0, 0.15), 0.06, 5);
        let far = vec![DVec2::new(6.0, 0.0)];
        let right = arc(DVec2::new(2.0, -0.15), 0.06, 5);
        let points: Vec<DVec2> = left.iter().chain(&far).chain(&right).copied().collect();
        let clusters = run(&points);
        assert_eq!(clusters.len(), 1, "{clusters:?}");
        assert_eq!(clusters[0].points.len(), 10);
        assert!((clusters[0].centroid - DVec2::new(2.0, 0.0)).length() < 0.1);
    }

    #[test]
    fn separate_objects_stay_separate_and_noise_is_dropped() {
        let mut points = arc(DVec2::new(1.0, 1.0), 0.2, 8);
        points.push(DVec2::new(3.0, 3.0)); // a stray return
        points.extend(arc(DVec2::new(-2.0, 1.0), 0.2, 8));
        let clusters = run(&points);
        assert_eq!(clusters.len(), 2);
    }

    #[test]
    fn first_and_last_beams_of_a_full_rotation_join() {
        let mut points = vec![DVec2::new(2.0, 0.0), DVec2::new(2.0, 0.05)];
        points.extend(arc(DVec2::new(-3.0, 0.0), 0.2, 6));
        points.push(DVec2::new(2.0, -0.05));
        let clusters = run(&points);
        assert_eq!(clusters.len(), 2);
        assert!(clusters.iter().any(|c| c.points.len() == 3));
    }

    #[test]
    fn walls_are_too_large_for_a_person() {
        let wall: Vec<DVec2> = (0..60).map(|i| DVec2::new(i as f64 * 0.05, 2.0)).collect();
        assert!(run(&wall).is_empty());
    }

    #[test]
    fn no_points_no_clusters() {
        assert!(run(&[]).is_empty());
    }
}
