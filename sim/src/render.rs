//! Draws what a camera of the rig would see: a checkered table, each arm's links, its gripper
//! fingers at their current opening, and the cube, all projected through a pinhole model. Crude
//! next to a photo, but every pixel follows from the simulated state, so images and actions
//! are correlated the way a policy needs.

use glam::{DMat3, DMat4, DVec3};
use scaledp_schema::rig::Camera;

use crate::scene::{Scene, SceneState};

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

fn look_at(eye: DVec3, target: DVec3) -> DMat4 {
    let z = (target - eye).normalize();
    let x = z.cross(DVec3::Z).normalize();
    let y = z.cross(x);
    DMat4::from_cols(x.extend(0.0), y.extend(0.0), z.extend(0.0), eye.extend(1.0))
}

impl View {
    /// Mounts camera `index` of the rig: a camera whose name contains "wrist" rides on the arm
    /// whose name it also contains (else the first arm); the others look at the workspace from
    /// the front, spread sideways.
    pub fn for_camera(scene: &Scene, cam: &Camera, index: usize) -> Self {
        let hfov = if cam.model == scaledp_schema::rig::CameraModel::Zed {
            1.75
        } else {
            1.2
        };
        let f_px = f64::from(cam.width) / 2.0 / (hfov / 2.0_f64).tan();
        let arms: Vec<_> = scene.arms().collect();
        let mount = if cam.name.contains("wrist") && !arms.is_empty() {
            let arm = arms
                .iter()
                .position(|(a, _)| cam.name.contains(a.name.as_str()))
                .unwrap_or(0);
            // 6 cm off the flange axis, tilted towards it, looking along the tool.
            let flange_from_camera = DMat4::from_translation(DVec3::new(0.09, 0.0, -0.04))
                * DMat4::from_rotation_y(-0.3);
            Mount::Wrist {
                arm,
                flange_from_camera,
            }
        } else {
            let state = scene.state_at(0.0);
            let n = state.arms.len().max(1) as f64;
            let target = state.arms.iter().map(|a| a.cube_world).sum::<DVec3>() / n;
            let bases = state
                .arms
                .iter()
                .map(|a| a.world_from_base.w_axis.truncate())
                .sum::<DVec3>()
                / n;
            let mut out = (target - bases).with_z(0.0);
            if out.length() < 1e-6 {
                out = DVec3::X;
            }
            let side = DVec3::Z.cross(out.normalize()) * (index as f64 * 0.35);
            let eye = target + out.normalize() * 0.75 + side + DVec3::new(0.0, 0.0, 0.6);
            Mount::World(look_at(eye, target + DVec3::new(0.0, 0.0, 0.12)))
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

    fn world_from_camera(&self, scene: &Scene, state: &SceneState) -> DMat4 {
        match self.mount {
            Mount::World(t) => t,
            Mount::Wrist {
                arm,
                flange_from_camera,
            } => {
                let (a, _) = scene
                    .arms()
                    .nth(arm)
                    .unwrap_or_else(|| unreachable!("mounted on an existing arm"));
                let s = &state.arms[arm];
                let flange = a.model.base_from_flange(&s.q).unwrap_or(DMat4::IDENTITY);
                s.world_from_base * flange * flange_from_camera
            }
        }
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

    /// A segment of radius `r` pixels from `a` to `b` (pixel coordinates).
    fn segment(&mut self, a: (f64, f64), b: (f64, f64), r: f64, rgb: [u8; 3]) {
        let r = r.clamp(1.0, 60.0);
        let x0 = (a.0.min(b.0) - r).floor().max(0.0) as usize;
        let y0 = (a.1.min(b.1) - r).floor().max(0.0) as usize;
        let x1 = ((a.0.max(b.0) + r).ceil().max(0.0) as usize).min(self.width);
        let y1 = ((a.1.max(b.1) + r).ceil().max(0.0) as usize).min(self.height);
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

const ARM_RGB: [[u8; 3]; 2] = [[225, 228, 232], [70, 120, 210]];

/// Renders `state` as camera `view` sees it into `out` (tightly packed rows in `encoding`).
pub fn render(
    scene: &Scene,
    view: &View,
    state: &SceneState,
    encoding: &str,
    table_z: f64,
    out: &mut Vec<u8>,
) {
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

    // Table: intersect each pixel's ray with the plane z = table_z; a 10 cm checker shaded by
    // distance, a plain wall where the ray misses.
    for y in 0..view.height {
        let v = (y as f64 + 0.5 - view.cy) / view.f_px;
        let row0 = rot * DVec3::new(-view.cx / view.f_px, v, 1.0);
        let step = rot * DVec3::new(1.0 / view.f_px, 0.0, 0.0);
        for x in 0..view.width {
            let d = row0 + step * (x as f64 + 0.5);
            let rgb = if d.z < -1e-6 {
                let t = (table_z - eye.z) / d.z;
                let p = eye + d * t;
                let check = ((p.x * 10.0).floor() as i64 + (p.y * 10.0).floor() as i64) & 1;
                let shade = (1.0 / (1.0 + 0.25 * t)).clamp(0.3, 1.0);
                let base = if check == 0 { 150.0 } else { 105.0 };
                let g = (base * shade) as u8;
                [g, (f64::from(g) * 0.95) as u8, (f64::from(g) * 0.85) as u8]
            } else {
                [182, 196, 210]
            };
            canvas.put(x, y, rgb);
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

    for (i, ((arm, _), s)) in scene.arms().zip(&state.arms).enumerate() {
        // The cube (5 cm), drawn as a shaded blob: a near-side face and its outline.
        let c = s.cube_world;
        seg(
            &mut canvas,
            c - DVec3::new(0.0, 0.0, 0.012),
            c + DVec3::new(0.0, 0.0, 0.012),
            0.026,
            [150, 20, 25],
        );
        seg(
            &mut canvas,
            c - DVec3::new(0.0, 0.0, 0.01),
            c + DVec3::new(0.0, 0.0, 0.01),
            0.021,
            [215, 40, 45],
        );

        let Ok(frames) = arm.model.frames(&s.q) else {
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
        // Gripper: a palm across the tool y axis and two fingers at ± width / 2.
        let flange = s.world_from_base * frames[frames.len() - 1];
        let tcp = flange * super::scene::flange_from_fingertips(arm);
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

/// Height of the table: just under the lowest point the cubes are picked from or placed at.
pub fn table_height(scene: &Scene) -> f64 {
    let mut z = f64::INFINITY;
    for k in 0..200 {
        let s = scene.state_at(k as f64 * 0.2);
        for a in &s.arms {
            z = z.min(a.cube_world.z);
        }
    }
    if z.is_finite() {
        z - 0.03
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use scaledp_schema::rig::Rig;

    use super::*;

    const CUBE_RGB: [[u8; 3]; 2] = [[215, 40, 45], [150, 20, 25]];

    /// The Franka rig with 160×120 cameras: camera 0 ("front") is fixed in the world, camera 1
    /// ("wrist") rides on the flange.
    fn rig() -> Rig {
        let mut rig = Rig::builtin("franka_2zed").unwrap();
        for c in &mut rig.cameras {
            c.width = 160;
            c.height = 120;
        }
        rig
    }

    fn draw(scene: &Scene, view: &View, state: &SceneState) -> Vec<u8> {
        let mut out = Vec::new();
        render(scene, view, state, "rgb8", table_height(scene), &mut out);
        out
    }

    fn pixel(img: &[u8], view: &View, (x, y): (f64, f64)) -> [u8; 3] {
        let i = (y as usize * view.width + x as usize) * 3;
        [img[i], img[i + 1], img[i + 2]]
    }

    /// (x, y, depth) of world point `p` in `view`, as the renderer projects it.
    fn project(scene: &Scene, view: &View, state: &SceneState, p: DVec3) -> (f64, f64, f64) {
        let c = view
            .world_from_camera(scene, state)
            .inverse()
            .transform_point3(p);
        assert!(c.z > 0.03, "{p} is behind the camera");
        (
            view.cx + view.f_px * c.x / c.z,
            view.cy + view.f_px * c.y / c.z,
            c.z,
        )
    }

    /// Pixels (x, y) where two images of `view` differ.
    fn changed(view: &View, a: &[u8], b: &[u8]) -> Vec<(f64, f64)> {
        (0..view.width * view.height)
            .filter(|i| a[i * 3..i * 3 + 3] != b[i * 3..i * 3 + 3])
            .map(|i| ((i % view.width) as f64 + 0.5, (i / view.width) as f64 + 0.5))
            .collect()
    }

    fn inside(view: &View, (x, y): (f64, f64)) -> bool {
        (0.0..view.width as f64).contains(&x) && (0.0..view.height as f64).contains(&y)
    }

    #[test]
    fn the_cube_is_drawn_where_it_projects_and_nothing_else_changes() {
        let rig = rig();
        let scene = Scene::new(&rig, 1);
        let view = View::for_camera(&scene, &rig.cameras[0], 0);
        assert!(matches!(view.mount, Mount::World(_)));
        let a = scene.state_at(0.0);
        let mut b = a.clone();
        b.arms[0].cube_world += DVec3::new(0.0, 0.12, 0.0);
        let (img_a, img_b) = (draw(&scene, &view, &a), draw(&scene, &view, &b));
        assert_eq!(img_a.len(), 160 * 120 * 3);
        assert_eq!(
            img_a,
            draw(&scene, &view, &a),
            "rendering is a pure function"
        );

        let pa = project(&scene, &view, &a, a.arms[0].cube_world);
        let pb = project(&scene, &view, &b, b.arms[0].cube_world);
        for p in [pa, pb] {
            assert!(inside(&view, (p.0, p.1)), "cube out of view at {p:?}");
        }
        assert_eq!(pixel(&img_a, &view, (pa.0, pa.1)), CUBE_RGB[0]);
        assert_eq!(pixel(&img_b, &view, (pb.0, pb.1)), CUBE_RGB[0]);
        assert!(!CUBE_RGB.contains(&pixel(&img_b, &view, (pa.0, pa.1))));
        assert!(!CUBE_RGB.contains(&pixel(&img_a, &view, (pb.0, pb.1))));
        // Only the cube moved: every changed pixel lies within the cube's drawn radius (plus
        // its 1.2 cm half-height and a pixel of rounding) of where it was or now is.
        let changed = changed(&view, &img_a, &img_b);
        assert!(changed.len() > 10, "{} pixels changed", changed.len());
        for (x, y) in changed {
            let near = [pa, pb].iter().any(|&(px, py, depth)| {
                let r = view.f_px * (0.026 + 0.012) / depth + 1.5;
                (x - px).hypot(y - py) <= r
            });
            assert!(near, "pixel ({x}, {y}) changed, away from the cube");
        }
    }

    #[test]
    fn the_gripper_opening_is_drawn_at_the_fingers() {
        let rig = rig();
        let scene = Scene::new(&rig, 1);
        let view = View::for_camera(&scene, &rig.cameras[0], 0);
        let open = scene.state_at(0.0);
        assert!(open.arms[0].gripper_width_m > 0.07);
        let mut closed = open.clone();
        closed.arms[0].gripper_width_m = 0.0;
        let changed = changed(
            &view,
            &draw(&scene, &view, &open),
            &draw(&scene, &view, &closed),
        );
        assert!(!changed.is_empty(), "the gripper opening is not drawn");
        // The fingers run from the palm (5 cm behind the TCP) to the TCP, ± (width / 2 + 8 mm)
        // along the tool y axis: every changed pixel is within the box of those points
        // (finger radius 6 mm, palm radius 1 cm, a pixel of rounding).
        let (arm, _) = scene.arms().next().unwrap();
        let s = &open.arms[0];
        let flange = s.world_from_base * arm.model.base_from_flange(&s.q).unwrap();
        let tcp = flange * super::super::scene::flange_from_fingertips(arm);
        let (o, y_axis, z_axis) = (
            tcp.w_axis.truncate(),
            tcp.y_axis.truncate(),
            tcp.z_axis.truncate(),
        );
        let mut corners = Vec::new();
        for end in [o, o - z_axis * 0.05] {
            for off in [-0.048, 0.048, -0.008, 0.008] {
                corners.push(project(&scene, &view, &open, end + y_axis * off));
            }
        }
        let depth = corners.iter().map(|c| c.2).fold(f64::INFINITY, f64::min);
        let pad = view.f_px * 0.01 / depth + 1.5;
        let (x0, x1) = corners.iter().fold((f64::MAX, f64::MIN), |(lo, hi), c| {
            (lo.min(c.0 - pad), hi.max(c.0 + pad))
        });
        let (y0, y1) = corners.iter().fold((f64::MAX, f64::MIN), |(lo, hi), c| {
            (lo.min(c.1 - pad), hi.max(c.1 + pad))
        });
        for (x, y) in changed {
            assert!(
                (x0..=x1).contains(&x) && (y0..=y1).contains(&y),
                "pixel ({x}, {y}) changed outside the gripper's box x {x0}..{x1}, y {y0}..{y1}"
            );
        }
    }

    #[test]
    fn the_wrist_camera_moves_with_the_arm_and_the_front_camera_does_not() {
        let rig = rig();
        let scene = Scene::new(&rig, 1);
        let front = View::for_camera(&scene, &rig.cameras[0], 0);
        let wrist = View::for_camera(&scene, &rig.cameras[1], 1);
        assert!(matches!(wrist.mount, Mount::Wrist { arm: 0, .. }));
        // Rest, then the arm lowered to the pick (the cube not yet lifted).
        let (a, b) = (
            scene.state_at(0.0),
            scene.state_at(0.25 * super::super::scene::CYCLE_S),
        );
        assert_ne!(a.arms[0].q, b.arms[0].q);
        assert_eq!(a.arms[0].cube_world, b.arms[0].cube_world);
        assert_eq!(
            front.world_from_camera(&scene, &a),
            front.world_from_camera(&scene, &b)
        );
        assert_ne!(
            wrist.world_from_camera(&scene, &a),
            wrist.world_from_camera(&scene, &b)
        );
        let n = (wrist.width * wrist.height) as f64;
        let moved = changed(&wrist, &draw(&scene, &wrist, &a), &draw(&scene, &wrist, &b));
        assert!(
            moved.len() as f64 > 0.2 * n,
            "{} of {n} changed",
            moved.len()
        );
        // Above the pick, the wrist camera looks down at the cube.
        let p = project(&scene, &wrist, &b, b.arms[0].cube_world);
        assert!(
            inside(&wrist, (p.0, p.1)),
            "cube out of the wrist view: {p:?}"
        );
    }

    #[test]
    fn every_encoding_holds_the_same_picture() {
        let rig = rig();
        let scene = Scene::new(&rig, 2);
        let view = View::for_camera(&scene, &rig.cameras[0], 0);
        let state = scene.state_at(1.3);
        let table_z = table_height(&scene);
        let encode = |encoding: &str| {
            let mut out = Vec::new();
            render(&scene, &view, &state, encoding, table_z, &mut out);
            out
        };
        let rgb = encode("rgb8");
        for (encoding, channels) in [("bgr8", 3), ("rgba8", 4), ("bgra8", 4), ("mono8", 1)] {
            let img = encode(encoding);
            assert_eq!(img.len(), view.width * view.height * channels, "{encoding}");
            for (px, src) in img.chunks(channels).zip(rgb.chunks(3)) {
                let (r, g, b) = (src[0], src[1], src[2]);
                let want: Vec<u8> = match encoding {
                    "bgr8" => vec![b, g, r],
                    "rgba8" => vec![r, g, b, 255],
                    "bgra8" => vec![b, g, r, 255],
                    _ => vec![
                        ((u16::from(r) * 77 + u16::from(g) * 150 + u16::from(b) * 29) >> 8) as u8,
                    ],
                };
                assert_eq!(px, want, "{encoding}");
            }
        }
    }
}
