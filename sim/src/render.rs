//! Draws what a camera of the rig would see: a checkered table with each cube's target marker,
//! the cubes (shaded faces, a shadow when lifted), each arm's links and its gripper fingers at
//! their current opening, all projected through a pinhole model. Crude next to a photo, but
//! every pixel follows from the simulated state, so images and actions are correlated the way a
//! policy needs; colours are chosen to stay distinct after downscaling to 96 × 96.

use glam::{DMat3, DMat4, DVec3};
use scaledp_schema::rig::{Camera, CameraModel};

use crate::scene::{Scene, CUBE_HALF_M, TABLE_Z_M};
use crate::world::WorldState;

/// Cube colours (red, blue), lit top face first then the two side shades.
pub const CUBE_RGB: [[[u8; 3]; 3]; 2] = [
    [[235, 45, 40], [190, 30, 28], [145, 20, 20]],
    [[50, 110, 240], [35, 80, 190], [25, 55, 140]],
];
/// Target marker colours (green for the red cube, yellow for the blue one): fill, border.
pub const TARGET_RGB: [[[u8; 3]; 2]; 2] = [
    [[60, 200, 80], [20, 110, 35]],
    [[235, 205, 40], [150, 120, 10]],
];
/// Half the side of a target marker (m).
pub const TARGET_HALF_M: f64 = 0.035;
const ARM_RGB: [[u8; 3]; 2] = [[225, 228, 232], [170, 175, 185]];

/// Where a camera sits and how it projects (OpenCV convention: z forward, x right, y down).
#[derive(Debug, Clone, Copy)]
pub enum Mount {
    /// Fixed in the world.
    World(DMat4),
    /// On an arm's flange: `flange_from_camera`.
    Wrist {
        /// Arm index.
        arm: usize,
        /// Camera pose in the flange frame.
        flange_from_camera: DMat4,
    },
}

/// A camera's mount and intrinsics.
#[derive(Debug, Clone, Copy)]
pub struct View {
    mount: Mount,
    f_px: f64,
    cx: f64,
    cy: f64,
    width: usize,
    height: usize,
}

/// Horizontal field of view (rad): a fixed ZED with the 4 mm lens (ZED 2i / ZED X: about 75°),
/// a ZED Mini on a wrist (about 90°), a RealSense D435's colour sensor (69°).
pub fn horizontal_fov_rad(model: CameraModel, wrist: bool) -> f64 {
    match (model, wrist) {
        (CameraModel::Zed, false) => 75f64.to_radians(),
        (CameraModel::Zed, true) => 90f64.to_radians(),
        // A simulator camera in the built-in cell is drawn as a RealSense.
        (CameraModel::Realsense | CameraModel::Sim, _) => 69f64.to_radians(),
    }
}

fn look_at(eye: DVec3, target: DVec3) -> DMat4 {
    let z = (target - eye).normalize();
    let x = z.cross(DVec3::Z).normalize();
    let y = z.cross(x);
    DMat4::from_cols(x.extend(0.0), y.extend(0.0), z.extend(0.0), eye.extend(1.0))
}

impl View {
    /// Mounts camera `index` of the rig: a camera whose name contains "wrist" rides on the arm
    /// whose name it also contains (else the first arm); the others look down at the workspace
    /// from across the table (facing the arms), spread sideways. The placement never depends on
    /// the seed.
    pub fn for_camera(scene: &Scene, cam: &Camera, index: usize) -> Self {
        let arms = scene.arms();
        let wrist = cam.name.contains("wrist") && !arms.is_empty();
        let hfov = match cam.vertical_fov_deg {
            Some(v) => {
                let aspect = f64::from(cam.width) / f64::from(cam.height);
                2.0 * ((v.to_radians() / 2.0).tan() * aspect).atan()
            }
            None => horizontal_fov_rad(cam.model, wrist),
        };
        let f_px = f64::from(cam.width) / 2.0 / (hfov / 2.0_f64).tan();
        let mount = if wrist {
            let arm = arms
                .iter()
                .position(|a| cam.name.contains(a.arm.name.as_str()))
                .unwrap_or(0);
            // 9 cm off the flange axis across the fingers, 4 cm behind the flange, tilted
            // towards the fingertips, which show at the bottom of the picture, left and right.
            let turn = DMat3::from_mat4(arms[arm].flange_from_fingertips);
            let flange_from_camera = DMat4::from_mat3(turn)
                * DMat4::from_translation(DVec3::new(0.09, 0.0, -0.04))
                * DMat4::from_rotation_z(std::f64::consts::FRAC_PI_2)
                * DMat4::from_rotation_x(-0.3);
            Mount::Wrist {
                arm,
                flange_from_camera,
            }
        } else {
            let target = scene.workspace_center();
            let mut out = (target - scene.bases_center()).with_z(0.0);
            if out.length() < 1e-6 {
                out = DVec3::X;
            }
            let out = out.normalize();
            let side = DVec3::Z.cross(out);
            // Far enough that every work region, plus a margin for the arms, spans 85 % of
            // the width, looking down at 50°.
            let half_extent = arms
                .iter()
                .map(|a| (a.region_center - target).dot(side).abs() + a.region_half.y)
                .fold(0.0, f64::max)
                + 0.22;
            let distance = half_extent / (hfov / 2.0).tan() / 0.85;
            let elevation = 50f64.to_radians();
            let eye = target
                + out * (distance * elevation.cos())
                + side * (index as f64 * 0.35)
                + DVec3::Z * (distance * elevation.sin());
            Mount::World(look_at(eye, target + DVec3::new(-0.05, 0.0, 0.1)))
        };
        Self {
            mount,
            f_px,
            cx: f64::from(cam.width) / 2.0,
            cy: f64::from(cam.height) / 2.0,
            width: cam.width as usize,
            height: cam.height as usize,
        }
    }

    /// The mount.
    pub fn mount(&self) -> Mount {
        self.mount
    }

    /// `world_from_camera` in `state`.
    pub fn world_from_camera(&self, scene: &Scene, state: &WorldState) -> DMat4 {
        match self.mount {
            Mount::World(t) => t,
            Mount::Wrist {
                arm,
                flange_from_camera,
            } => {
                let a = &scene.arms()[arm];
                a.world_from_base * a.base_from_flange(&state.arms[arm].q) * flange_from_camera
            }
        }
    }

    /// Pixel (x, y) and depth of world point `p` in `state`, if in front of the camera.
    pub fn project(&self, scene: &Scene, state: &WorldState, p: DVec3) -> Option<(f64, f64, f64)> {
        let c = self
            .world_from_camera(scene, state)
            .inverse()
            .transform_point3(p);
        (c.z > 0.03).then(|| {
            (
                self.cx + self.f_px * c.x / c.z,
                self.cy + self.f_px * c.y / c.z,
                c.z,
            )
        })
    }

    /// (width, height) in pixels.
    pub fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// The pinhole intrinsics: focal length and principal point (pixels), `(f, cx, cy)`.
    pub fn intrinsics(&self) -> (f64, f64, f64) {
        (self.f_px, self.cx, self.cy)
    }
}

/// Pixel writer for one encoding.
struct Canvas<'a> {
    buf: &'a mut [u8],
    width: usize,
    height: usize,
    channels: usize,
    order: [usize; 3],
}

impl Canvas<'_> {
    #[inline]
    fn put(&mut self, x: usize, y: usize, rgb: [u8; 3]) {
        let i = (y * self.width + x) * self.channels;
        let px = &mut self.buf[i..i + self.channels];
        if self.channels == 1 {
            px[0] = ((u16::from(rgb[0]) * 77 + u16::from(rgb[1]) * 150 + u16::from(rgb[2]) * 29)
                >> 8) as u8;
            return;
        }
        for (c, &src) in self.order.iter().enumerate() {
            px[c] = rgb[src];
        }
        if self.channels == 4 {
            px[3] = 255;
        }
    }

    /// Pixel bounds (x0..x1, y0..y1) of a box, clipped to the canvas.
    fn bounds(&self, lo: (f64, f64), hi: (f64, f64)) -> (usize, usize, usize, usize) {
        let clip = |v: f64, max: usize| (v.max(0.0) as usize).min(max);
        (
            clip(lo.0.floor(), self.width),
            clip(hi.0.ceil(), self.width),
            clip(lo.1.floor(), self.height),
            clip(hi.1.ceil(), self.height),
        )
    }

    /// A segment of radius `r` pixels from `a` to `b` (pixel coordinates).
    fn segment(&mut self, a: (f64, f64), b: (f64, f64), r: f64, rgb: [u8; 3]) {
        let r = r.clamp(1.0, 60.0);
        let (x0, x1, y0, y1) = self.bounds(
            (a.0.min(b.0) - r, a.1.min(b.1) - r),
            (a.0.max(b.0) + r, a.1.max(b.1) + r),
        );
        let (dx, dy) = (b.0 - a.0, b.1 - a.1);
        let len2 = (dx * dx + dy * dy).max(1e-9);
        for y in y0..y1 {
            for x in x0..x1 {
                let (px, py) = (x as f64 + 0.5 - a.0, y as f64 + 0.5 - a.1);
                let s = ((px * dx + py * dy) / len2).clamp(0.0, 1.0);
                let (ex, ey) = (px - s * dx, py - s * dy);
                if ex * ex + ey * ey <= r * r {
                    self.put(x, y, rgb);
                }
            }
        }
    }

    /// A filled convex polygon (pixel coordinates, either winding).
    fn polygon(&mut self, pts: &[(f64, f64)], rgb: [u8; 3]) {
        let lo = pts
            .iter()
            .fold((f64::MAX, f64::MAX), |a, p| (a.0.min(p.0), a.1.min(p.1)));
        let hi = pts
            .iter()
            .fold((f64::MIN, f64::MIN), |a, p| (a.0.max(p.0), a.1.max(p.1)));
        let (x0, x1, y0, y1) = self.bounds(lo, hi);
        let n = pts.len();
        for y in y0..y1 {
            for x in x0..x1 {
                let (px, py) = (x as f64 + 0.5, y as f64 + 0.5);
                let (mut pos, mut neg) = (false, false);
                for i in 0..n {
                    let (a, b) = (pts[i], pts[(i + 1) % n]);
                    let e = (b.0 - a.0) * (py - a.1) - (b.1 - a.1) * (px - a.0);
                    pos |= e > 0.0;
                    neg |= e < 0.0;
                }
                if !(pos && neg) {
                    self.put(x, y, rgb);
                }
            }
        }
    }
}

/// Channel count and RGB→buffer order for a ROS encoding.
pub fn layout(encoding: &str) -> Option<(usize, [usize; 3])> {
    match encoding {
        "rgb8" => Some((3, [0, 1, 2])),
        "bgr8" => Some((3, [2, 1, 0])),
        "rgba8" => Some((4, [0, 1, 2])),
        "bgra8" => Some((4, [2, 1, 0])),
        "mono8" => Some((1, [0, 1, 2])),
        _ => None,
    }
}

/// The table's colour where a ray from `eye` along `d` meets it (or the wall's).
#[inline]
fn table_pixel(eye: DVec3, d: DVec3, targets: &[(DVec3, usize)], shadows: &[DVec3]) -> [u8; 3] {
    if d.z >= -1e-6 {
        return [182, 196, 210];
    }
    let t = (TABLE_Z_M - eye.z) / d.z;
    let p = eye + d * t;
    for &(c, k) in targets {
        let (dx, dy) = ((p.x - c.x).abs(), (p.y - c.y).abs());
        if dx <= TARGET_HALF_M && dy <= TARGET_HALF_M {
            let inner = TARGET_HALF_M - 0.006;
            return TARGET_RGB[k % 2][usize::from(dx > inner || dy > inner)];
        }
    }
    // A faint 15 cm checker: texture for depth, too soft to turn into noise when downscaled.
    let check = ((p.x / 0.15).floor() as i64 + (p.y / 0.15).floor() as i64) & 1;
    let mut shade = (1.0 / (1.0 + 0.25 * t)).clamp(0.3, 1.0);
    if shadows
        .iter()
        .any(|s| (p - *s).truncate().length_squared() < 0.03 * 0.03)
    {
        shade *= 0.55;
    }
    let base = if check == 0 { 168.0 } else { 150.0 };
    let g = (base * shade) as u8;
    [g, (f64::from(g) * 0.95) as u8, (f64::from(g) * 0.85) as u8]
}

/// Renders `state` as camera `view` sees it into `out` (tightly packed rows in `encoding`).
pub fn render(scene: &Scene, view: &View, state: &WorldState, encoding: &str, out: &mut Vec<u8>) {
    let (channels, order) = layout(encoding).unwrap_or((3, [0, 1, 2]));
    out.resize(view.width * view.height * channels, 0);
    let mut canvas = Canvas {
        buf: out,
        width: view.width,
        height: view.height,
        channels,
        order,
    };
    let world_from_camera = view.world_from_camera(scene, state);
    let rot = DMat3::from_mat4(world_from_camera);
    let eye = world_from_camera.w_axis.truncate();
    let camera_from_world = world_from_camera.inverse();
    let cubes = &state.task.cubes;
    let targets: Vec<(DVec3, usize)> = cubes
        .iter()
        .enumerate()
        .map(|(k, c)| (DVec3::from_array(c.target_m), k))
        .collect();
    let shadows: Vec<DVec3> = cubes
        .iter()
        .map(|c| DVec3::from_array(c.position_m))
        .filter(|p| p.z > TABLE_Z_M + CUBE_HALF_M + 0.003)
        .collect();

    // Table: intersect each pixel's ray with the plane z = TABLE_Z_M; a 10 cm checker shaded by
    // distance, the target markers and cube shadows on it, a plain wall where the ray misses.
    let step = rot * DVec3::new(1.0 / view.f_px, 0.0, 0.0);
    for y in 0..view.height {
        let v = (y as f64 + 0.5 - view.cy) / view.f_px;
        let row0 = rot * DVec3::new(-view.cx / view.f_px, v, 1.0);
        for x in 0..view.width {
            let d = row0 + step * (x as f64 + 0.5);
            canvas.put(x, y, table_pixel(eye, d, &targets, &shadows));
        }
    }

    let project = |p: DVec3| -> Option<(f64, f64, f64)> {
        let c = camera_from_world.transform_point3(p);
        (c.z > 0.03).then(|| {
            (
                view.cx + view.f_px * c.x / c.z,
                view.cy + view.f_px * c.y / c.z,
                c.z,
            )
        })
    };
    let seg = |canvas: &mut Canvas, a: DVec3, b: DVec3, radius_m: f64, rgb: [u8; 3]| {
        if let (Some(pa), Some(pb)) = (project(a), project(b)) {
            let r = view.f_px * radius_m / pa.2.min(pb.2);
            canvas.segment((pa.0, pa.1), (pb.0, pb.1), r, rgb);
        }
    };

    // Cubes, the farthest first: each visible face as a filled quad.
    let mut order: Vec<usize> = (0..cubes.len()).collect();
    let depth = |k: usize| (DVec3::from_array(cubes[k].position_m) - eye).length();
    order.sort_by(|a, b| depth(*b).total_cmp(&depth(*a)));
    for k in order {
        let c = &cubes[k];
        let pose = DMat4::from_translation(DVec3::from_array(c.position_m))
            * DMat4::from_rotation_z(c.yaw_rad);
        let h = CUBE_HALF_M;
        for (normal, shade) in [
            (DVec3::Z, 0),
            (DVec3::X, 1),
            (-DVec3::X, 1),
            (DVec3::Y, 2),
            (-DVec3::Y, 2),
        ] {
            let centre = pose.transform_point3(normal * h);
            let n = pose.transform_vector3(normal);
            if n.dot(eye - centre) <= 0.0 {
                continue;
            }
            let (u, w) = if normal.z != 0.0 {
                (DVec3::X, DVec3::Y)
            } else {
                (normal.cross(DVec3::Z), DVec3::Z)
            };
            let corners: Option<Vec<(f64, f64)>> =
                [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
                    .iter()
                    .map(|(a, b)| {
                        project(pose.transform_point3(normal * h + u * (a * h) + w * (b * h)))
                            .map(|p| (p.0, p.1))
                    })
                    .collect();
            if let Some(corners) = corners {
                canvas.polygon(&corners, CUBE_RGB[k % 2][shade]);
            }
        }
    }

    for (i, (layout, s)) in scene.arms().iter().zip(&state.arms).enumerate() {
        let Ok(frames) = layout.arm.model.frames(&s.q) else {
            continue;
        };
        let mut prev = s.world_from_base.w_axis.truncate();
        for f in &frames {
            let p = (s.world_from_base * *f).w_axis.truncate();
            if (p - prev).length() > 1e-4 {
                seg(&mut canvas, prev, p, 0.04, ARM_RGB[i % 2]);
            }
            prev = p;
        }
        // Gripper: a palm across the fingertip y axis and two fingers at ± width / 2.
        let tcp = s.world_from_base * frames[frames.len() - 1] * layout.flange_from_fingertips;
        let (o, y_axis, z_axis) = (
            tcp.w_axis.truncate(),
            tcp.y_axis.truncate(),
            tcp.z_axis.truncate(),
        );
        let palm = o - z_axis * 0.05;
        seg(
            &mut canvas,
            palm - y_axis * 0.05,
            palm + y_axis * 0.05,
            0.01,
            [40, 40, 45],
        );
        for side in [-1.0, 1.0] {
            let off = y_axis * (side * (s.gripper_width_m / 2.0 + 0.008));
            seg(&mut canvas, palm + off, o + off, 0.006, [25, 25, 28]);
        }
    }
}

#[cfg(test)]
mod tests;
