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
        let (mut t0, mut t1) = (0.0f64, t_max);
        for a in 0..3 {
            let (n, f) = ((self.min[a] - o[a]) * inv[a], (self.max[a] - o[a]) * inv[a]);
            // NaN (0 * inf on a face) falls through min/max, keeping the ray conservative.
            t0 = t0.max(n.min(f));
            t1 = t1.min(n.max(f));
        }
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

    /// Smallest ray parameter t in (EPS, t_max) where origin + t·dir meets the surface.
    fn hit(&self, o: &[f64; 3], d: &[f64; 3], t_max: f64) -> Option<f64> {
        match *self {
            Shape::Box { centre, half, yaw } => {
                // Into the box's frame: rotate by -yaw about z.
                let (s, c) = yaw.sin_cos();
                let (px, py) = (o[0] - centre[0], o[1] - centre[1]);
                let lo = [c * px + s * py, -s * px + c * py, o[2] - centre[2]];
                let ld = [c * d[0] + s * d[1], -s * d[0] + c * d[1], d[2]];
                let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
                for a in 0..3 {
                    if ld[a] == 0.0 {
                        if lo[a].abs() > half[a] {
                            return None;
                        }
                        continue;
                    }
                    let inv = 1.0 / ld[a];
                    let (n, f) = ((-half[a] - lo[a]) * inv, (half[a] - lo[a]) * inv);
                    t0 = t0.max(n.min(f));
                    t1 = t1.min(n.max(f));
                }
                nearest_valid(t0, t1, t_max)
            }
            Shape::Cylinder {
                x,
                y,
                radius,
                z_min,
                z_max,
            } => {
                let (px, py) = (o[0] - x, o[1] - y);
                let a = d[0] * d[0] + d[1] * d[1];
                let b = px * d[0] + py * d[1];
                let c = px * px + py * py - radius * radius;
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
                    let (n, f) = ((z_min - o[2]) / d[2], (z_max - o[2]) / d[2]);
                    t0 = t0.max(n.min(f));
                    t1 = t1.min(n.max(f));
                }
                nearest_valid(t0, t1, t_max)
            }
        }
    }
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
    shapes: Vec<Shape>,
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
        let shapes = order.iter().map(|&i| shapes[i]).collect();
        Scene { shapes, nodes }
    }

    pub fn len(&self) -> usize {
        self.shapes.len()
    }

    pub fn is_empty(&self) -> bool {
        self.shapes.is_empty()
    }

    /// Distance parameter t of the first hit along origin + t·dir before t_max.
    pub fn cast(&self, o: &[f64; 3], d: &[f64; 3], t_max: f64) -> Option<f64> {
        if self.shapes.is_empty() {
            return None;
        }
        let inv = d.map(|v| 1.0 / v);
        let mut best = t_max;
        let mut hit = false;
        let mut stack = [0u32; 64];
        let mut top = 1;
        while top > 0 {
            top -= 1;
            let node = &self.nodes[stack[top] as usize];
            if node.bounds.enter(o, &inv, best).is_none() {
                continue;
            }
            if node.count > 0 {
                let first = node.first as usize;
                for s in &self.shapes[first..first + node.count as usize] {
                    if let Some(t) = s.hit(o, d, best) {
                        best = t;
                        hit = true;
                    }
                }
            } else {
                // Visit the nearer child first so `best` shrinks early.
                let (l, r) = (node.first, node.first + 1);
                let tl = self.nodes[l as usize].bounds.enter(o, &inv, best);
                let tr = self.nodes[r as usize].bounds.enter(o, &inv, best);
                let (near, far) = match (tl, tr) {
                    (Some(a), Some(b)) if b < a => (Some(r), Some(l)),
                    (Some(_), Some(_)) => (Some(l), Some(r)),
                    (Some(_), None) => (Some(l), None),
                    (None, Some(_)) => (Some(r), None),
                    (None, None) => (None, None),
                };
                for child in [far, near].into_iter().flatten() {
                    stack[top] = child;
                    top += 1;
                }
            }
        }
        hit.then_some(best)
    }

    /// A pinhole depth image (z-depth, 0 where nothing is hit within `max_depth`), row-major.
    /// `pose` is the camera→world transform (row-major 4x4; camera z forward, x right, y down).
    pub fn depth_image(&self, pose: &[f64; 16], cam: &Pinhole, max_depth: f64) -> Vec<f32> {
        let o = [pose[3], pose[7], pose[11]];
        let mut out = vec![0f32; cam.width * cam.height];
        out.par_chunks_mut(cam.width)
            .enumerate()
            .for_each(|(v, row)| {
                let y = (v as f64 - cam.cy) / cam.fy;
                for (u, px) in row.iter_mut().enumerate() {
                    // Unnormalised direction with z = 1 in the camera: t is the z-depth itself.
                    let c = [(u as f64 - cam.cx) / cam.fx, y, 1.0];
                    let d = rotate(pose, &c);
                    *px = self.cast(&o, &d, max_depth).map_or(0.0, |t| t as f32);
                }
            });
        out
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

/// Median split on the widest axis of the centroids, recursively.
fn build(nodes: &mut Vec<Node>, at: usize, order: &mut [usize], offset: usize, b: &[Aabb]) {
    let bounds = order.iter().fold(Aabb::empty(), |acc, &i| acc.union(b[i]));
    if order.len() <= LEAF_SIZE {
        nodes[at] = Node {
            bounds,
            first: offset as u32,
            count: order.len() as u32,
        };
        return;
    }
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
    let left = nodes.len();
    nodes.push(Node {
        bounds: Aabb::empty(),
        first: 0,
        count: 0,
    });
    nodes.push(Node {
        bounds: Aabb::empty(),
        first: 0,
        count: 0,
    });
    nodes[at] = Node {
        bounds,
        first: left as u32,
        count: 0,
    };
    let (lo, hi) = order.split_at_mut(mid);
    build(nodes, left, lo, offset, b);
    build(nodes, left + 1, hi, offset + mid, b);
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

    #[test]
    fn bvh_matches_brute_force() {
        let mut shapes = Vec::new();
        for i in 0..60 {
            let f = i as f64;
            shapes.push(Shape::Box {
                centre: [
                    (f * 1.7) % 9.0 - 4.5,
                    (f * 2.3) % 7.0 - 3.5,
                    (f * 0.9) % 3.0,
                ],
                half: [0.2 + (f % 3.0) * 0.1, 0.3, 0.25],
                yaw: f * 0.3,
            });
            shapes.push(Shape::Cylinder {
                x: (f * 3.1) % 9.0 - 4.5,
                y: (f * 1.3) % 7.0 - 3.5,
                radius: 0.15,
                z_min: 0.0,
                z_max: 2.0,
            });
        }
        let scene = Scene::new(shapes.clone());
        for i in 0..2000 {
            let a = i as f64 * 0.0317;
            let (o, d) = ([0.1, -0.2, 1.0], [a.cos(), a.sin(), (a * 7.0).sin() * 0.3]);
            let brute = shapes
                .iter()
                .filter_map(|s| s.hit(&o, &d, 50.0))
                .fold(f64::INFINITY, f64::min);
            let got = scene.cast(&o, &d, 50.0).unwrap_or(f64::INFINITY);
            assert_eq!(got, brute, "ray {i}");
        }
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
