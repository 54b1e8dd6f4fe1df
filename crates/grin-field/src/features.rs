//! Where an `expr` field has features a step could pass over unseen, and how long a step
//! may be there. A Runge-Kutta step samples the field at a few points; a feature between
//! them (a tall narrow bump off the axis) is invisible to the step and to its error
//! estimate (dopri's pilots reported 0 rad while the rays were 0.76 rad off). Analytic
//! kinds know their scales and grids their node spacing; a formula has neither, so grin
//! finds its scales with interval arithmetic (crate::interval) over the formula's exact
//! partial derivatives.
//!
//! An octree over the bounds' box: a box is *resolved* when the enclosure of each
//! component of grad n over the whole box is at most [`OVERESTIMATE`] times the largest
//! |grad n| component sampled at its corners and centre (what a step there sees), or when
//! even the whole enclosure could turn a ray crossing the box by at most
//! [`NEGLIGIBLE_RAD`]. Otherwise the variation
//! the samples cannot see may hide a feature, and the box is split in eight, largest
//! first, down to [`MIN_BOX_REL`] of the bounds or [`MAX_BOXES`] boxes. A step from a
//! point is then at most half the smallest leaf within its reach, so its stages land in
//! every box it crosses. Smooth formulas (a GRIN rod's polynomial) are resolved at the
//! root and cost nothing.

use glam::DVec3;

use crate::bounds::Bounds;
use crate::interval::Interval;

/// A box is resolved when each grad n component's enclosure is at most this many times
/// the largest sampled component (interval arithmetic overestimates smooth functions by
/// a small factor; a hidden feature's gradient is orders of magnitude above what the
/// samples around it see).
pub const OVERESTIMATE: f64 = 4.0;
/// ... or when the enclosure's width times the box's size over n is at most this (rad):
/// no variation of that size can matter.
pub const NEGLIGIBLE_RAD: f64 = 1e-7;
/// Smallest box, as a fraction of the bounds' longest side.
pub const MIN_BOX_REL: f64 = 1.0 / 4096.0;
/// Most boxes the octree may hold; past it the largest unresolved boxes stay leaves
/// ([`FeatureMap::unresolved`] counts them).
pub const MAX_BOXES: usize = 1 << 17;
/// A step is at most this fraction of the smallest leaf within its reach.
pub const STEP_FRACTION: f64 = 0.5;
/// Points of the finest leaves (within 4x of the finest size) handed to a bake's error
/// search, at most.
pub const MAX_FEATURE_POINTS: usize = 4096;

#[derive(Debug, Clone, Copy)]
struct Node {
    lo: DVec3,
    hi: DVec3,
    /// Index of the first of eight children; 0 for a leaf.
    children: u32,
    /// Smallest leaf size (longest side) in this subtree.
    min_leaf: f64,
}

/// The field as the map needs it: grad n at a point, grad n and n enclosed over a box.
pub trait Enclosed {
    fn grad_at(&self, p: DVec3) -> DVec3;
    fn grad_over(&self, lo: DVec3, hi: DVec3) -> [Interval; 3];
    /// The smallest n over the box (its enclosure's lower end, or a sampled value
    /// where the enclosure is no proof).
    fn n_min_over(&self, lo: DVec3, hi: DVec3) -> f64;
}

/// The octree of resolved boxes of one field (see the module's notes).
#[derive(Debug, Clone)]
pub struct FeatureMap {
    nodes: Vec<Node>,
    /// Leaves left unresolved at [`MIN_BOX_REL`] or when [`MAX_BOXES`] was reached.
    unresolved: usize,
    /// Centres of the finest leaves (for a bake's error search).
    points: Vec<DVec3>,
}

impl FeatureMap {
    /// Build the map of `field` over `bounds`.
    pub fn build(field: &dyn Enclosed, bounds: &Bounds) -> Self {
        let (lo, hi) = bounds.aabb();
        let min_size = MIN_BOX_REL * (hi - lo).max_element();
        let mut nodes = vec![Node {
            lo,
            hi,
            children: 0,
            min_leaf: (hi - lo).max_element(),
        }];
        // Largest unresolved boxes first.
        let mut queue = std::collections::BinaryHeap::new();
        if !resolved(field, bounds, lo, hi) {
            queue.push(Pending(size(lo, hi), 0));
        }
        let mut unresolved = 0;
        while let Some(Pending(s, i)) = queue.pop() {
            if s <= min_size || nodes.len() + 8 > MAX_BOXES {
                unresolved += 1;
                continue;
            }
            let Node { lo, hi, .. } = nodes[i];
            let mid = (lo + hi) * 0.5;
            let first = nodes.len();
            nodes[i].children = first as u32;
            for k in 0..8 {
                let pick = |bit: usize, a: f64, m: f64, b: f64| {
                    if k & bit == 0 { (a, m) } else { (m, b) }
                };
                let (x0, x1) = pick(1, lo.x, mid.x, hi.x);
                let (y0, y1) = pick(2, lo.y, mid.y, hi.y);
                let (z0, z1) = pick(4, lo.z, mid.z, hi.z);
                let (a, b) = (DVec3::new(x0, y0, z0), DVec3::new(x1, y1, z1));
                nodes.push(Node {
                    lo: a,
                    hi: b,
                    children: 0,
                    min_leaf: size(a, b),
                });
                if !resolved(field, bounds, a, b) {
                    queue.push(Pending(size(a, b), first + k));
                }
            }
        }
        // Subtree minima, children before parents (children always come later).
        for i in (0..nodes.len()).rev() {
            let c = nodes[i].children as usize;
            if c != 0 {
                nodes[i].min_leaf = nodes[c..c + 8]
                    .iter()
                    .map(|n| n.min_leaf)
                    .fold(f64::INFINITY, f64::min);
            }
        }
        let root = size(nodes[0].lo, nodes[0].hi);
        let finest = nodes[0].min_leaf;
        let mut leaves: Vec<&Node> = nodes
            .iter()
            .filter(|n| n.children == 0 && n.min_leaf < root && n.min_leaf <= 4.0 * finest)
            .collect();
        leaves.sort_by(|a, b| a.min_leaf.total_cmp(&b.min_leaf));
        let points = leaves
            .iter()
            .take(MAX_FEATURE_POINTS)
            .map(|n| (n.lo + n.hi) * 0.5)
            .filter(|p| bounds.contains(*p))
            .collect();
        FeatureMap {
            nodes,
            unresolved,
            points,
        }
    }

    /// Whether [`Self::step_cap`] is finite anywhere (the map found a feature).
    pub fn has_caps(&self) -> bool {
        self.nodes[0].children != 0
    }

    /// The longest step from `p` that puts a stage in every box it can reach: half the
    /// smallest leaf within `reach` of `p` (infinite where the whole field is resolved at
    /// the root).
    pub fn step_cap(&self, p: DVec3, reach: f64) -> f64 {
        if self.nodes[0].children == 0 {
            return f64::INFINITY;
        }
        let (a, b) = (p - reach, p + reach);
        let mut best = f64::INFINITY;
        let mut stack = vec![0usize];
        while let Some(i) = stack.pop() {
            let n = &self.nodes[i];
            if n.min_leaf >= best || (n.lo.cmpgt(b).any() || n.hi.cmplt(a).any()) {
                continue;
            }
            if n.children == 0 {
                best = n.min_leaf;
            } else {
                let c = n.children as usize;
                stack.extend(c..c + 8);
            }
        }
        STEP_FRACTION * best
    }

    /// The smallest leaf (longest side): the finest scale found.
    pub fn finest(&self) -> f64 {
        self.nodes[0].min_leaf
    }

    /// Boxes in the octree.
    pub fn boxes(&self) -> usize {
        self.nodes.len()
    }

    /// Leaves still unresolved at the size or box limit.
    pub fn unresolved(&self) -> usize {
        self.unresolved
    }

    /// Centres of the finest leaves inside the bounds (at most [`MAX_FEATURE_POINTS`]).
    pub fn points(&self) -> &[DVec3] {
        &self.points
    }
}

/// A box waiting to be split, by size (largest first).
#[derive(Debug, PartialEq)]
struct Pending(f64, usize);
impl Eq for Pending {}
impl PartialOrd for Pending {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Pending {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.0.total_cmp(&other.0).then(other.1.cmp(&self.1))
    }
}

fn size(lo: DVec3, hi: DVec3) -> f64 {
    (hi - lo).max_element()
}

/// Whether the box [lo, hi] is resolved (see the module's notes). Boxes outside the
/// bounds are (no ray samples there).
fn resolved(field: &dyn Enclosed, bounds: &Bounds, lo: DVec3, hi: DVec3) -> bool {
    if !bounds.meets_box(lo, hi, 0.0) {
        return true;
    }
    let enclosure = field.grad_over(lo, hi);
    let width = enclosure.map(|g| g.hi - g.lo);
    if width.iter().any(|w| !w.is_finite()) {
        return false;
    }
    let c = size(lo, hi);
    let n_min = field.n_min_over(lo, hi);
    if n_min > 0.0 && c * width.iter().fold(0.0f64, |m, w| m.max(*w)) / n_min <= NEGLIGIBLE_RAD {
        return true;
    }
    // The largest |grad n| the samples see: the variation the step's own samples show
    // is of this size, and interval arithmetic overestimates a smooth function's range
    // by a small factor of it (also at an extremum of a component, where the samples'
    // spread is second order in the box).
    let mut seen = 0.0f64;
    let corners = (0..8).map(|k| {
        DVec3::new(
            if k & 1 == 0 { lo.x } else { hi.x },
            if k & 2 == 0 { lo.y } else { hi.y },
            if k & 4 == 0 { lo.z } else { hi.z },
        )
    });
    for p in corners.chain([(lo + hi) * 0.5]) {
        // (A sphere's box corners lie outside it, where a formula may not be defined.)
        let g = field.grad_at(crate::interval::clamp_into(bounds, p));
        if !g.is_finite() {
            return false;
        }
        seen = seen.max(g.abs().max_element());
    }
    // Variation under NEGLIGIBLE_RAD's share is no feature either.
    let floor = if n_min > 0.0 {
        NEGLIGIBLE_RAD * n_min / c
    } else {
        0.0
    };
    width.iter().all(|w| *w <= OVERESTIMATE * seen + floor)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// n = 1 + a exp(-|p - c|^2 / w^2), with exact interval bounds of its gradient
    /// (monotone pieces), for testing the map without the expression machinery.
    struct Bump {
        a: f64,
        w: f64,
        c: DVec3,
    }

    impl Enclosed for Bump {
        fn grad_at(&self, p: DVec3) -> DVec3 {
            let d = p - self.c;
            d * (-2.0 * self.a / (self.w * self.w)
                * (-d.length_squared() / (self.w * self.w)).exp())
        }
        fn grad_over(&self, lo: DVec3, hi: DVec3) -> [Interval; 3] {
            // |dn/dx| <= 2a/w^2 |x - cx| exp(-(dist to the box)^2 / w^2), sign-free.
            let near = (self.c.clamp(lo, hi) - self.c).length_squared();
            let e = (-near / (self.w * self.w)).exp();
            let far = (lo - self.c).abs().max((hi - self.c).abs());
            let m = far * (2.0 * self.a / (self.w * self.w) * e);
            [0, 1, 2].map(|k| Interval {
                lo: -m[k],
                hi: m[k],
            })
        }
        fn n_min_over(&self, _: DVec3, _: DVec3) -> f64 {
            1.0
        }
    }

    fn unit() -> Bounds {
        Bounds::Box {
            min: DVec3::splat(-1.0),
            max: DVec3::splat(1.0),
        }
    }

    /// A bump 1/100 of the bounds wide, off the axis: the map refines around it, caps
    /// steps there at a fraction of its width, and leaves the far field uncapped enough.
    #[test]
    fn a_narrow_bump_is_found_and_caps_steps_near_it() {
        let c = DVec3::new(0.3, -0.2, 0.1);
        let bump = Bump {
            a: 0.05,
            w: 0.02,
            c,
        };
        let map = FeatureMap::build(&bump, &unit());
        assert_eq!(map.unresolved(), 0, "{} boxes", map.boxes());
        assert!(map.has_caps());
        eprintln!("bump map: {} boxes, finest {}", map.boxes(), map.finest());
        assert!(map.finest() <= 0.02, "finest {}", map.finest());
        // A step that could reach the bump is shorter than its width.
        assert!(map.step_cap(c + DVec3::new(0.05, 0.0, 0.0), 0.1) < 0.02);
        assert!(map.step_cap(c, 0.001) < 0.02);
        // Far from it, steps are free to be long.
        assert!(map.step_cap(DVec3::new(-0.8, 0.8, -0.8), 0.1) >= 0.1);
        // The finest leaves' centres lie on the bump.
        assert!(!map.points().is_empty());
        assert!(map.points().iter().all(|p| p.distance(c) < 0.2));
    }

    /// A linear gradient (a GRIN rod's n is quadratic) is resolved at the root: no cap.
    #[test]
    fn a_smooth_field_costs_nothing() {
        struct Linear;
        impl Enclosed for Linear {
            fn grad_at(&self, p: DVec3) -> DVec3 {
                DVec3::new(-0.1 * p.x, -0.1 * p.y, 0.0)
            }
            fn grad_over(&self, lo: DVec3, hi: DVec3) -> [Interval; 3] {
                [
                    Interval {
                        lo: -0.1 * hi.x,
                        hi: -0.1 * lo.x,
                    },
                    Interval {
                        lo: -0.1 * hi.y,
                        hi: -0.1 * lo.y,
                    },
                    Interval::point(0.0),
                ]
            }
            fn n_min_over(&self, _: DVec3, _: DVec3) -> f64 {
                1.5
            }
        }
        let map = FeatureMap::build(&Linear, &unit());
        assert_eq!(map.boxes(), 1);
        assert!(!map.has_caps());
        assert_eq!(map.step_cap(DVec3::ZERO, 1.0), f64::INFINITY);
    }
}
