//! Topological checks of input polygons: self-intersections, holes that
//! cross or leave their exterior.

use geo::line_intersection::{LineIntersection, line_intersection};
use geo::{Contains, Intersects};
use geo_types::{Coord, Line, LineString, Polygon};
use rstar::{AABB, RTree, RTreeObject};

use super::Issue;

/// At most this many intersections are reported per polygon: one is enough
/// to fix, and a pathological ring could otherwise yield millions.
const MAX_REPORTED: usize = 5;

struct Edge {
    ring: usize,
    index: usize,
    line: Line<f64>,
}

impl RTreeObject for Edge {
    type Envelope = AABB<[f64; 2]>;
    fn envelope(&self) -> Self::Envelope {
        AABB::from_corners(
            [self.line.start.x, self.line.start.y],
            [self.line.end.x, self.line.end.y],
        )
    }
}

/// Faults that make `polygon` unusable as an area: a ring that crosses or
/// touches itself, rings that cross each other, holes outside the exterior.
/// `pointer` is the JSON pointer of the polygon's `coordinates`.
pub fn polygon_issues(polygon: &Polygon<f64>, pointer: &str) -> Vec<Issue> {
    let rings: Vec<&LineString<f64>> = std::iter::once(polygon.exterior())
        .chain(polygon.interiors())
        .collect();
    let mut edges = Vec::new();
    for (r, ring) in rings.iter().enumerate() {
        for (index, line) in ring.lines().enumerate() {
            // Repeated consecutive positions are harmless: skip zero-length edges.
            if line.start != line.end {
                edges.push(Edge {
                    ring: r,
                    index,
                    line,
                });
            }
        }
    }
    let ring_len: Vec<usize> = rings.iter().map(|r| r.0.len().saturating_sub(1)).collect();
    let tree = RTree::bulk_load(edges);
    let mut issues = Vec::new();
    let mut pace = crate::cancel::Pacer::new(1024);
    'outer: for a in tree.iter() {
        if pace.tick().is_err() {
            // Cancelled: the caller checks again and reports it.
            break;
        }
        for b in tree.locate_in_envelope_intersecting(&a.envelope()) {
            if (b.ring, b.index) <= (a.ring, a.index) {
                continue;
            }
            let Some(hit) = line_intersection(a.line, b.line) else {
                continue;
            };
            let at = match hit {
                LineIntersection::SinglePoint { intersection, .. } => {
                    if a.ring == b.ring && adjacent(a.index, b.index, ring_len[a.ring]) {
                        // Neighbouring edges share their common vertex by construction.
                        let shared = if b.index == a.index + 1 {
                            a.line.end
                        } else {
                            a.line.start
                        };
                        if close(intersection, shared) {
                            continue;
                        }
                    }
                    intersection
                }
                LineIntersection::Collinear { intersection } => intersection.start,
            };
            let message = if a.ring == b.ring {
                format!(
                    "{} self-intersects at ({:.8}, {:.8}): edge {} meets edge {}",
                    ring_name(a.ring),
                    at.x,
                    at.y,
                    a.index,
                    b.index
                )
            } else {
                format!(
                    "{} and {} intersect at ({:.8}, {:.8})",
                    ring_name(a.ring),
                    ring_name(b.ring),
                    at.x,
                    at.y
                )
            };
            issues.push(Issue::new(&format!("{pointer}/{}", a.ring), &message));
            if issues.len() >= MAX_REPORTED {
                break 'outer;
            }
        }
    }
    if issues.is_empty() {
        let exterior = Polygon::new(polygon.exterior().clone(), vec![]);
        for (h, hole) in polygon.interiors().iter().enumerate() {
            let inside = hole.0.iter().any(|c| exterior.contains(c))
                || hole.0.iter().all(|c| exterior.intersects(c));
            if !inside {
                issues.push(Issue::new(
                    &format!("{pointer}/{}", h + 1),
                    &format!("hole {} lies outside the polygon's exterior ring", h + 1),
                ));
            }
        }
    }
    issues
}

fn adjacent(i: usize, j: usize, n: usize) -> bool {
    j == i + 1 || (i == 0 && j + 1 == n)
}

fn close(a: Coord<f64>, b: Coord<f64>) -> bool {
    (a.x - b.x).abs() <= 1e-12 && (a.y - b.y).abs() <= 1e-12
}

fn ring_name(r: usize) -> String {
    if r == 0 {
        "exterior ring".to_string()
    } else {
        format!("hole {r}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use geo_types::polygon;

    #[test]
    fn simple_polygons_pass() {
        let p = polygon![(x: 0.0, y: 0.0), (x: 2.0, y: 0.0), (x: 2.0, y: 2.0), (x: 0.0, y: 2.0)];
        assert!(polygon_issues(&p, "").is_empty());
        let with_hole = polygon!(
            exterior: [(x: 0.0, y: 0.0), (x: 2.0, y: 0.0), (x: 2.0, y: 2.0), (x: 0.0, y: 2.0)],
            interiors: [[(x: 0.5, y: 0.5), (x: 1.0, y: 0.5), (x: 1.0, y: 1.0)]],
        );
        assert!(polygon_issues(&with_hole, "").is_empty());
    }

    #[test]
    fn bow_tie_is_reported_with_its_crossing() {
        let p = polygon![(x: 0.0, y: 0.0), (x: 2.0, y: 2.0), (x: 2.0, y: 0.0), (x: 0.0, y: 2.0)];
        let issues = polygon_issues(&p, "/roi/coordinates");
        assert_eq!(issues.len(), 1, "{issues:?}");
        assert_eq!(issues[0].pointer, "/roi/coordinates/0");
        assert!(
            issues[0]
                .message
                .contains("self-intersects at (1.00000000, 1.00000000)")
        );
    }

    #[test]
    fn ring_touching_itself_and_collinear_overlap() {
        // Figure-of-eight through a repeated vertex.
        let p = polygon![(x: 0.0, y: 0.0), (x: 1.0, y: 1.0), (x: 2.0, y: 0.0), (x: 2.0, y: 2.0), (x: 1.0, y: 1.0), (x: 0.0, y: 2.0)];
        assert!(!polygon_issues(&p, "").is_empty());
        // A spike folding back on its own edge.
        let p = polygon![(x: 0.0, y: 0.0), (x: 2.0, y: 0.0), (x: 1.0, y: 0.0), (x: 1.0, y: 1.0)];
        assert!(!polygon_issues(&p, "").is_empty());
    }

    #[test]
    fn holes_crossing_or_outside_are_reported() {
        let crossing = polygon!(
            exterior: [(x: 0.0, y: 0.0), (x: 2.0, y: 0.0), (x: 2.0, y: 2.0), (x: 0.0, y: 2.0)],
            interiors: [[(x: 1.0, y: 1.0), (x: 3.0, y: 1.0), (x: 3.0, y: 1.5)]],
        );
        assert!(
            polygon_issues(&crossing, "")[0]
                .message
                .contains("intersect")
        );
        let outside = polygon!(
            exterior: [(x: 0.0, y: 0.0), (x: 2.0, y: 0.0), (x: 2.0, y: 2.0), (x: 0.0, y: 2.0)],
            interiors: [[(x: 5.0, y: 5.0), (x: 6.0, y: 5.0), (x: 6.0, y: 6.0)]],
        );
        assert!(polygon_issues(&outside, "")[0].message.contains("outside"));
    }
}
