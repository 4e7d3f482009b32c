//! Ray casting against worlds of primitives (yawed boxes and vertical cylinders) through a
//! bounding-volume hierarchy: the simulator's depth camera and LiDAR.

use rayon::prelude::*;

/// Hits closer than this are ignored, so a ray leaving a surface does not hit it again.
const EPS: f64 = 1e-9;

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Shape {
    /// A box of half extents `half` centred at `centre`, rotated by `yaw` about +z.
    Box {
        centre: [f64; 3],
        half: [f64; 3],
        yaw: f64,
    },
    /// An upright cylinder of `radius` around (x, y), from `z_min` to `z_max`.
    Cylinder {
        x: f64,
        y: f64,
        radius: f64,
        z_min: f64,
        z_max: f64,
    },
}

/// A shape prepared for intersection: boxes whose yaw is a multiple of 90° become axis-aligned
/// (the common case: walls, floors, furniture), others keep their precomputed rotation.
#[derive(Debug, Clone, Copy)]
enum Prim {
    Aligned(Aabb),
    Rotated {
        centre: [f64; 3],
        half: [f64; 3],
        cos: f64,
        sin: f64,
    },
    Cylinder {
        x: f64,
        y: f64,
        r2: f64,
        z_min: f64,
        z_max: f64,
    },
}

#[derive(Debug, Clone, Copy)]
struct Aabb {
    min: [f64; 3],
    max: [f64; 3],
}

impl Aabb {
    fn empty() -> Aabb {
        Aabb {
            min: [f64::INFINITY; 3],
            max: [f64::NEG_INFINITY; 3],
        }
    }

    fn union(self, o: Aabb) -> Aabb {
        Aabb {
            min: [0, 1, 2].map(|a| self.min[a].min(o.min[a])),
            max: [0, 1, 2].map(|a| self.max[a].max(o.max[a])),
        }
    }

    fn centre(&self, a: usize) -> f64 {
        0.5 * (self.min[a] + self.max[a])
    }

    /// Entry distance of the ray into the box if it enters before `t_max`.
    #[inline(always)]
    fn enter(&self, o: &[f64; 3], inv: &[f64; 3], t_max: f64) -> Option<f64> {
        let (t0, t1) = slabs(&self.min, &self.max, o, inv);
        let (t0, t1) = (t0.max(0.0), t1.min(t_max));
        (t0 <= t1).then_some(t0)
    }
}

impl Shape {
    fn bounds(&self) -> Aabb {
        match *self {
            Shape::Box { centre, half, yaw } => {
                let (s, c) = yaw.sin_cos();
                let ex = (c * half[0]).abs() + (s * half[1]).abs();
                let ey = (s * half[0]).abs() + (c * half[1]).abs();
                let e = [ex, ey, half[2]];
                Aabb {
                    min: [0, 1, 2].map(|a| centre[a] - e[a]),
                    max: [0, 1, 2].map(|a| centre[a] + e[a]),
                }
            }
            Shape::Cylinder {
                x,
                y,
                radius,
                z_min,
                z_max,
            } => Aabb {
                min: [x - radius, y - radius, z_min],
                max: [x + radius, y + radius, z_max],
            },
        }
    }

    fn prepare(&self) -> Prim {
        match *self {
            Shape::Box { centre, half, yaw } => {
                let quarter = yaw / std::f64::consts::FRAC_PI_2;
                if (quarter - quarter.round()).abs() < 1e-12 {
                    Prim::Aligned(self.bounds())
                } else {
                    let (sin, cos) = yaw.sin_cos();
                    Prim::Rotated {
                        centre,
                        half,
                        cos,
                        sin,
                    }
                }
            }
            Shape::Cylinder {
                x,
                y,
                radius,
                z_min,
                z_max,
            } => Prim::Cylinder {
                x,
                y,
                r2: radius * radius,
                z_min,
                z_max,
            },
        }
    }
}

impl Prim {
    /// Smallest ray parameter t in (EPS, t_max) where origin + t·dir meets the surface;
    /// `inv` is 1/dir per axis.
    #[inline(always)]
    fn hit(&self, o: &[f64; 3], d: &[f64; 3], inv: &[f64; 3], t_max: f64) -> Option<f64> {
        match *self {
            Prim::Aligned(b) => {
                let (t0, t1) = slabs(&b.min, &b.max, o, inv);
                nearest_valid(t0, t1, t_max)
            }
            Prim::Rotated {
                centre,
                half,
                cos: c,
                sin: s,
            } => {
                // Into the box's frame: rotate by -yaw about z.
                let (px, py) = (o[0] - centre[0], o[1] - centre[1]);
                let lo = [c * px + s * py, -s * px + c * py, o[2] - centre[2]];
                let ld = [c * d[0] + s * d[1], -s * d[0] + c * d[1], d[2]];
                let linv = ld.map(|v| 1.0 / v);
                let (t0, t1) = slabs(&half.map(|h| -h), &half, &lo, &linv);
                nearest_valid(t0, t1, t_max)
            }
            Prim::Cylinder {
                x,
                y,
                r2,
                z_min,
                z_max,
            } => {
                let (px, py) = (o[0] - x, o[1] - y);
                let a = d[0] * d[0] + d[1] * d[1];
                let b = px * d[0] + py * d[1];
                let c = px * px + py * py - r2;
                // Interval of t inside the infinite cylinder.
                let (mut t0, mut t1) = if a == 0.0 {
                    if c > 0.0 {
                        return None;
                    }
                    (f64::NEG_INFINITY, f64::INFINITY)
                } else {
                    let disc = b * b - a * c;
                    if disc < 0.0 {
                        return None;
                    }
                    let r = disc.sqrt();
                    ((-b - r) / a, (-b + r) / a)
                };
                // Intersect with the slab z_min..z_max (this also handles the caps).
                if d[2] == 0.0 {
                    if o[2] < z_min || o[2] > z_max {
                        return None;
                    }
                } else {
                    let (n, f) = ((z_min - o[2]) * inv[2], (z_max - o[2]) * inv[2]);
                    t0 = t0.max(n.min(f));
                    t1 = t1.min(n.max(f));
                }
                nearest_valid(t0, t1, t_max)
            }
        }
    }
}

/// Entry and exit parameters of a ray through an axis-aligned box (entry > exit: a miss).
/// A direction component of zero gives ±inf, or NaN on a face, which min/max absorb so a ray
/// along a face counts as inside (conservative for rays grazing walls).
#[inline(always)]
fn slabs(min: &[f64; 3], max: &[f64; 3], o: &[f64; 3], inv: &[f64; 3]) -> (f64, f64) {
    let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
    for a in 0..3 {
        let (n, f) = ((min[a] - o[a]) * inv[a], (max[a] - o[a]) * inv[a]);
        t0 = t0.max(n.min(f));
        t1 = t1.min(n.max(f));
    }
    (t0, t1)
}

/// The first crossing of the interval [t0, t1] in front of the origin, if before t_max.
fn nearest_valid(t0: f64, t1: f64, t_max: f64) -> Option<f64> {
    if t0 > t1 {
        return None;
    }
    let t = if t0 > EPS { t0 } else { t1 };
    (t > EPS && t < t_max).then_some(t)
}

#[derive(Debug, Clone, Copy)]
struct Node {
    bounds: Aabb,
    /// Leaf: first shape index and count; inner: left child index (right = left + 1), count 0.
    first: u32,
    count: u32,
}

const LEAF_SIZE: usize = 2;

/// A world ready for ray casting.
#[derive(Debug, Clone)]
pub struct Scene {
    prims: Vec<Prim>,
    /// Bounds of each primitive (same order as `prims`).
    bounds: Vec<Aabb>,
    nodes: Vec<Node>,
}

impl Scene {
    pub fn new(shapes: Vec<Shape>) -> Scene {
        let bounds: Vec<Aabb> = shapes.iter().map(Shape::bounds).collect();
        let mut order: Vec<usize> = (0..shapes.len()).collect();
        let mut nodes = vec![Node {
            bounds: Aabb::empty(),
            first: 0,
            count: 0,
        }];
        if !shapes.is_empty() {
            build(&mut nodes, 0, &mut order, 0, &bounds);
        }
        let prims = order.iter().map(|&i| shapes[i].prepare()).collect();
        let bounds = order.iter().map(|&i| bounds[i]).collect();
        Scene {
            prims,
            bounds,
            nodes,
        }
    }

    pub fn len(&self) -> usize {
        self.prims.len()
    }

    pub fn is_empty(&self) -> bool {
        self.prims.is_empty()
    }

    /// Distance parameter t of the first hit along origin + t·dir before t_max.
    pub fn cast(&self, o: &[f64; 3], d: &[f64; 3], t_max: f64) -> Option<f64> {
        self.cast_with(o, d, t_max, &mut Caster::default())
    }

    /// `cast` with reusable scratch: the traversal stack (no per-ray allocation or zeroing) and
    /// the last ray's hit, tried first because neighbouring rays mostly hit the same surface.
    /// The result is the same as `cast`.
    fn cast_with(&self, o: &[f64; 3], d: &[f64; 3], t_max: f64, c: &mut Caster) -> Option<f64> {
        let inv = d.map(|v| 1.0 / v);
        let mut best = t_max;
        let mut hit = false;
        let (stack, hint) = (&mut c.stack, &mut c.hint);
        stack.clear();
        if let Some(h) = *hint {
            if let Some(t) = self.prims[h as usize].hit(o, d, &inv, best) {
                best = t;
                hit = true;
            }
        }
        // Nodes to visit with their entry distance: skipped once a closer hit is known.
        if let Some(t) = self.nodes[0].bounds.enter(o, &inv, best) {
            stack.push((0, t));
        }
        while let Some((index, entry)) = stack.pop() {
            if entry > best {
                continue;
            }
            let node = &self.nodes[index as usize];
            if node.count > 0 {
                let first = node.first as usize;
                for (k, p) in self.prims[first..first + node.count as usize]
                    .iter()
                    .enumerate()
                {
                    if let Some(t) = p.hit(o, d, &inv, best) {
                        best = t;
                        hit = true;
                        *hint = Some((first + k) as u32);
                    }
                }
                continue;
            }
            let (l, r) = (node.first, node.first + 1);
            let tl = self.nodes[l as usize].bounds.enter(o, &inv, best);
            let tr = self.nodes[r as usize].bounds.enter(o, &inv, best);
            // Push the farther child first so the nearer one is visited first.
            let mut push = |child: u32, t: Option<f64>| {
                if let Some(t) = t {
                    stack.push((child, t));
                }
            };
            if tl.unwrap_or(f64::INFINITY) <= tr.unwrap_or(f64::INFINITY) {
                push(r, tr);
                push(l, tl);
            } else {
                push(l, tl);
                push(r, tr);
            }
        }
        hit.then_some(best)
    }

    /// A pinhole depth image (z-depth, 0 where nothing is hit within `max_depth`), row-major.
    /// `pose` is the camera→world transform (row-major 4x4; camera z forward, x right, y down).
    pub fn depth_image(&self, pose: &[f64; 16], cam: &Pinhole, max_depth: f64) -> Vec<f32> {
        let o = [pose[3], pose[7], pose[11]];
        // Unnormalised direction with z = 1 in the camera: t is the z-depth itself.
        let dir = |u: usize, v: usize| {
            rotate(
                pose,
                &[
                    (u as f64 - cam.cx) / cam.fx,
                    (v as f64 - cam.cy) / cam.fy,
                    1.0,
                ],
            )
        };
        let mut out = vec![0f32; cam.width * cam.height];
        out.par_chunks_mut(cam.width * TILE)
            .enumerate()
            .for_each(|(ty, band)| {
                let mut packet = Packet::default();
                let rows = band.len() / cam.width;
                for u0 in (0..cam.width).step_by(TILE) {
                    let (u1, v0) = ((u0 + TILE).min(cam.width) - 1, ty * TILE);
                    let v1 = v0 + rows - 1;
                    // The direction is affine in (u, v): its range over the tile is at the corners.
                    let corners = [dir(u0, v0), dir(u1, v0), dir(u0, v1), dir(u1, v1)];
                    self.gather(&o, &corners, max_depth, &mut packet);
                    for v in v0..=v1 {
                        for u in u0..=u1 {
                            let d = dir(u, v);
                            let t = self.first_hit(&o, &d, max_depth, &packet.candidates);
                            band[(v - v0) * cam.width + u] = t.map_or(0.0, |t| t as f32);
                        }
                    }
                }
            });
        out
    }

    /// Collects into `packet` every primitive that some ray of the tile spanned by `corners`
    /// may hit before `t_max`, with a lower bound of its distance, nearest first.
    fn gather(&self, o: &[f64; 3], corners: &[[f64; 3]; 4], t_max: f64, packet: &mut Packet) {
        let lo = [0, 1, 2].map(|a| corners.iter().map(|c| c[a]).fold(f64::INFINITY, f64::min));
        let hi = [0, 1, 2].map(|a| {
            corners
                .iter()
                .map(|c| c[a])
                .fold(f64::NEG_INFINITY, f64::max)
        });
        let reach = |b: &Aabb| packet_enter(b, o, &lo, &hi, t_max);
        packet.candidates.clear();
        packet.stack.clear();
        packet.stack.push(0);
        while let Some(i) = packet.stack.pop() {
            let node = &self.nodes[i as usize];
            if reach(&node.bounds).is_none() {
                continue;
            }
            if node.count == 0 {
                packet.stack.extend([node.first, node.first + 1]);
                continue;
            }
            for k in node.first..node.first + node.count {
                if let Some(t) = reach(&self.bounds[k as usize]) {
                    packet.candidates.push((t, k));
                }
            }
        }
        packet
            .candidates
            .sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    }

    /// The nearest hit among candidates sorted by their distance bound.
    fn first_hit(
        &self,
        o: &[f64; 3],
        d: &[f64; 3],
        t_max: f64,
        cands: &[(f64, u32)],
    ) -> Option<f64> {
        let inv = d.map(|v| 1.0 / v);
        let mut best = t_max;
        let mut hit = false;
        for &(bound, k) in cands {
            if bound > best {
                break; // every remaining candidate starts farther than the hit
            }
            if let Some(t) = self.prims[k as usize].hit(o, d, &inv, best) {
                best = t;
                hit = true;
            }
        }
        hit.then_some(best)
    }

    /// Ranges along unit directions given in the sensor frame (NaN where nothing is hit).
    pub fn ranges(&self, pose: &[f64; 16], dirs: &[[f64; 3]], max_range: f64) -> Vec<f64> {
        let o = [pose[3], pose[7], pose[11]];
        dirs.par_iter()
            .map(|s| {
                self.cast(&o, &rotate(pose, s), max_range)
                    .unwrap_or(f64::NAN)
            })
            .collect()
    }
}

/// Per-thread scratch of `Scene::cast_with`.
#[derive(Default)]
struct Caster {
    stack: Vec<(u32, f64)>,
    hint: Option<u32>,
}

/// Pixels per side of the square tiles a depth image is cast in.
const TILE: usize = 8;

/// Scratch of one tile: BVH stack and candidate primitives with their distance bounds.
#[derive(Default)]
struct Packet {
    stack: Vec<u32>,
    candidates: Vec<(f64, u32)>,
}

/// Conservative entry distance of a bundle of rays from `o` with directions in the box
/// [lo, hi] into an AABB: None only if no ray of the bundle can enter it before `t_max`.
/// Per axis, the slab interval [(min−o)/d, (max−o)/d] is monotone in d, so its hull over the
/// bundle comes from the end points; an axis where d changes sign constrains nothing.
#[inline(always)]
fn packet_enter(b: &Aabb, o: &[f64; 3], lo: &[f64; 3], hi: &[f64; 3], t_max: f64) -> Option<f64> {
    let (mut t0, mut t1) = (0.0f64, t_max);
    for a in 0..3 {
        let (near, far) = (b.min[a] - o[a], b.max[a] - o[a]);
        let (near, far) = if lo[a] > 0.0 {
            (near, far)
        } else if hi[a] < 0.0 {
            (far, near)
        } else {
            continue;
        };
        t0 = t0.max((near / lo[a]).min(near / hi[a]));
        t1 = t1.min((far / lo[a]).max(far / hi[a]));
    }
    (t0 <= t1).then_some(t0)
}

/// Pinhole intrinsics and image size.
#[derive(Debug, Clone, Copy)]
pub struct Pinhole {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub width: usize,
    pub height: usize,
}

#[inline(always)]
fn rotate(m: &[f64; 16], v: &[f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|r| m[4 * r] * v[0] + m[4 * r + 1] * v[1] + m[4 * r + 2] * v[2])
}

/// Binned surface-area-heuristic build: big shapes (floors, long walls) end up near the root
/// instead of inflating every node below it.
fn build(nodes: &mut Vec<Node>, at: usize, order: &mut [usize], offset: usize, b: &[Aabb]) {
    let bounds = order.iter().fold(Aabb::empty(), |acc, &i| acc.union(b[i]));
    let leaf = Node {
        bounds,
        first: offset as u32,
        count: order.len() as u32,
    };
    if order.len() <= LEAF_SIZE {
        nodes[at] = leaf;
        return;
    }
    let mid = match sah_split(order, b) {
        Some((axis, cut, cost)) if cost < order.len() as f64 * area(&bounds) => {
            let key = |i: &usize| b[*i].centre(axis) < cut;
            let mut mid = 0;
            for k in 0..order.len() {
                if key(&order[k]) {
                    order.swap(k, mid);
                    mid += 1;
                }
            }
            mid
        }
        _ if order.len() <= MAX_LEAF => {
            nodes[at] = leaf;
            return;
        }
        _ => 0,
    };
    let mid = if mid == 0 || mid == order.len() {
        median(order, b)
    } else {
        mid
    };
    let left = nodes.len();
    nodes.push(leaf);
    nodes.push(leaf);
    nodes[at] = Node {
        bounds,
        first: left as u32,
        count: 0,
    };
    let (lo, hi) = order.split_at_mut(mid);
    build(nodes, left, lo, offset, b);
    build(nodes, left + 1, hi, offset + mid, b);
}

const BINS: usize = 16;
const MAX_LEAF: usize = 8;

fn area(b: &Aabb) -> f64 {
    let d = [0, 1, 2].map(|a| (b.max[a] - b.min[a]).max(0.0));
    2.0 * (d[0] * d[1] + d[1] * d[2] + d[2] * d[0])
}

/// The best (axis, centroid cut, SAH cost) over binned candidate splits.
fn sah_split(order: &[usize], b: &[Aabb]) -> Option<(usize, f64, f64)> {
    let mut best: Option<(usize, f64, f64)> = None;
    for axis in 0..3 {
        let (lo, hi) = order
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &i| {
                (l.min(b[i].centre(axis)), h.max(b[i].centre(axis)))
            });
        if hi - lo <= 0.0 {
            continue;
        }
        let bin = |i: usize| {
            (((b[i].centre(axis) - lo) / (hi - lo) * BINS as f64) as usize).min(BINS - 1)
        };
        let mut boxes = [Aabb::empty(); BINS];
        let mut counts = [0usize; BINS];
        for &i in order {
            let k = bin(i);
            boxes[k] = boxes[k].union(b[i]);
            counts[k] += 1;
        }
        let mut right = [(Aabb::empty(), 0usize); BINS];
        let mut acc = (Aabb::empty(), 0);
        for k in (1..BINS).rev() {
            acc = (acc.0.union(boxes[k]), acc.1 + counts[k]);
            right[k] = acc;
        }
        let mut left = (Aabb::empty(), 0);
        for k in 1..BINS {
            left = (left.0.union(boxes[k - 1]), left.1 + counts[k - 1]);
            if left.1 == 0 || right[k].1 == 0 {
                continue;
            }
            let cost = area(&left.0) * left.1 as f64 + area(&right[k].0) * right[k].1 as f64;
            if best.is_none_or(|(_, _, c)| cost < c) {
                best = Some((axis, lo + (hi - lo) * k as f64 / BINS as f64, cost));
            }
        }
    }
    best
}

/// Median split on the widest centroid axis: the fallback when binning cannot separate.
fn median(order: &mut [usize], b: &[Aabb]) -> usize {
    let cb = order.iter().fold(Aabb::empty(), |acc, &i| {
        let c = [0, 1, 2].map(|a| b[i].centre(a));
        acc.union(Aabb { min: c, max: c })
    });
    let axis = (0..3)
        .max_by(|&x, &y| (cb.max[x] - cb.min[x]).total_cmp(&(cb.max[y] - cb.min[y])))
        .expect("three axes");
    let mid = order.len() / 2;
    order.select_nth_unstable_by(mid, |&x, &y| {
        b[x].centre(axis).total_cmp(&b[y].centre(axis))
    });
    mid
}

#[cfg(test)]
mod tests {
    use super::*;

    const IDENTITY: [f64; 16] = [
        1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1.,
    ];

    fn wall_at_x(x: f64) -> Shape {
        Shape::Box {
            centre: [x + 0.05, 0.0, 1.0],
            half: [0.05, 5.0, 1.0],
            yaw: 0.0,
        }
    }

    #[test]
    fn ray_against_a_wall_returns_the_analytic_distance() {
        let scene = Scene::new(vec![wall_at_x(3.0)]);
        let t = scene
            .cast(&[0.0, 0.0, 1.0], &[1.0, 0.0, 0.0], 100.0)
            .unwrap();
        assert!((t - 3.0).abs() < 1e-12);
        // At 30° off the normal the range is 3 / cos 30°.
        let a = 30f64.to_radians();
        let t = scene
            .cast(&[0.0, 0.0, 1.0], &[a.cos(), a.sin(), 0.0], 100.0)
            .unwrap();
        assert!((t - 3.0 / a.cos()).abs() < 1e-12);
        assert!(scene
            .cast(&[0.0, 0.0, 1.0], &[-1.0, 0.0, 0.0], 100.0)
            .is_none());
        assert!(scene
            .cast(&[0.0, 0.0, 1.0], &[1.0, 0.0, 0.0], 2.5)
            .is_none());
    }

    #[test]
    fn yawed_box_and_cylinder() {
        // A unit cube turned 45°: its corner points at the origin, 1 - sqrt(2)/2 short of x=1.
        let cube = Shape::Box {
            centre: [1.0, 0.0, 0.0],
            half: [0.5; 3],
            yaw: 45f64.to_radians(),
        };
        let pillar = Shape::Cylinder {
            x: -2.0,
            y: 0.0,
            radius: 0.25,
            z_min: 0.0,
            z_max: 2.0,
        };
        let scene = Scene::new(vec![cube, pillar]);
        let t = scene.cast(&[0.0; 3], &[1.0, 0.0, 0.0], 10.0).unwrap();
        assert!((t - (1.0 - 0.5 * 2f64.sqrt())).abs() < 1e-12);
        let t = scene
            .cast(&[0.0, 0.0, 1.0], &[-1.0, 0.0, 0.0], 10.0)
            .unwrap();
        assert!((t - 1.75).abs() < 1e-12);
        // Straight down onto the cylinder's top cap.
        let t = scene
            .cast(&[-2.1, 0.0, 5.0], &[0.0, 0.0, -1.0], 10.0)
            .unwrap();
        assert!((t - 3.0).abs() < 1e-12);
        assert!(scene
            .cast(&[0.0, 0.0, 2.5], &[-1.0, 0.0, 0.0], 10.0)
            .is_none());
    }

    /// `n` yawed boxes (centres up to `height`) and `n` pillars scattered over 9 x 7 m.
    fn clutter(n: usize, height: f64) -> Vec<Shape> {
        (0..n)
            .flat_map(|i| {
                let f = i as f64;
                [
                    Shape::Box {
                        centre: [
                            (f * 1.7) % 9.0 - 4.5,
                            (f * 2.3) % 7.0 - 3.5,
                            (f * 0.9) % height,
                        ],
                        half: [0.2 + (f % 3.0) * 0.1, 0.3, 0.25],
                        yaw: f * 0.3,
                    },
                    Shape::Cylinder {
                        x: (f * 3.1) % 9.0 - 4.5,
                        y: (f * 1.3) % 7.0 - 3.5,
                        radius: 0.15,
                        z_min: 0.0,
                        z_max: 2.0,
                    },
                ]
            })
            .collect()
    }

    #[test]
    fn bvh_matches_brute_force() {
        let shapes = clutter(60, 3.0);
        let scene = Scene::new(shapes.clone());
        for i in 0..2000 {
            let a = i as f64 * 0.0317;
            let (o, d) = ([0.1, -0.2, 1.0], [a.cos(), a.sin(), (a * 7.0).sin() * 0.3]);
            let inv = d.map(|v: f64| 1.0 / v);
            let brute = shapes
                .iter()
                .filter_map(|s| s.prepare().hit(&o, &d, &inv, 50.0))
                .fold(f64::INFINITY, f64::min);
            let got = scene.cast(&o, &d, 50.0).unwrap_or(f64::INFINITY);
            assert_eq!(got, brute, "ray {i}");
        }
    }

    #[test]
    fn tiled_depth_image_equals_per_ray_casts() {
        let floor = Shape::Box {
            centre: [0.0, 0.0, -0.05],
            half: [9.0, 9.0, 0.05],
            yaw: 0.0,
        };
        let mut shapes = clutter(40, 2.0);
        shapes.push(floor);
        let scene = Scene::new(shapes);
        let cam = Pinhole {
            fx: 100.0,
            fy: 100.0,
            cx: 49.5,
            cy: 37.5,
            width: 101,
            height: 77,
        };
        // Looking along +x (camera z) from 1 m above the floor, tilted down a little.
        let (c, s) = (0.2f64.cos(), 0.2f64.sin());
        let pose = [
            0., -s, c, -4.0, -1., 0., 0., 0.2, 0., -c, -s, 1.0, 0., 0., 0., 1.,
        ];
        let img = scene.depth_image(&pose, &cam, 20.0);
        for v in 0..cam.height {
            for u in 0..cam.width {
                let d = rotate(
                    &pose,
                    &[
                        (u as f64 - cam.cx) / cam.fx,
                        (v as f64 - cam.cy) / cam.fy,
                        1.0,
                    ],
                );
                let want = scene
                    .cast(&[-4.0, 0.2, 1.0], &d, 20.0)
                    .map_or(0.0, |t| t as f32);
                assert_eq!(img[v * cam.width + u], want, "pixel ({u}, {v})");
            }
        }
        assert!(img.iter().filter(|&&z| z > 0.0).count() > img.len() / 2);
    }

    #[test]
    fn depth_image_of_a_wall_is_flat() {
        let scene = Scene::new(vec![Shape::Box {
            centre: [0.0, 0.0, 2.05],
            half: [9.0, 9.0, 0.05],
            yaw: 0.0,
        }]);
        let cam = Pinhole {
            fx: 525.0,
            fy: 525.0,
            cx: 319.5,
            cy: 239.5,
            width: 640,
            height: 480,
        };
        let img = scene.depth_image(&IDENTITY, &cam, 10.0);
        assert!(img.iter().all(|&z| (z - 2.0).abs() < 1e-6));
        let far = scene.depth_image(&IDENTITY, &cam, 1.5);
        assert!(far.iter().all(|&z| z == 0.0));
    }
}
