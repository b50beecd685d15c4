//! The picture follows the state: cubes, targets, the gripper, the wrist camera.

use glam::DVec3;
use scaledp_schema::rig::Rig;

use super::*;
use crate::world::World;

/// The Franka rig with 160×120 cameras: camera 0 ("front") is fixed in the world, camera 1
/// ("wrist") rides on the flange.
fn rig() -> Rig {
    Rig::builtin("franka_2zed")
        .unwrap()
        .with_image_size(160, 120)
}

fn draw(scene: &Scene, view: &View, state: &WorldState) -> Vec<u8> {
    let mut out = Vec::new();
    render(scene, view, state, "rgb8", &mut out);
    out
}

fn pixel(img: &[u8], view: &View, (x, y): (f64, f64)) -> [u8; 3] {
    let i = (y as usize * view.width + x as usize) * 3;
    [img[i], img[i + 1], img[i + 2]]
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

fn cube_at(state: &WorldState, k: usize) -> DVec3 {
    DVec3::from_array(state.task.cubes[k].position_m)
}

#[test]
fn the_cube_is_drawn_where_it_projects_and_nothing_else_changes() {
    let rig = rig();
    let world = World::new(&rig, 1);
    let scene = world.scene();
    let view = View::for_camera(scene, &rig.cameras[0], 0);
    assert!(matches!(view.mount, Mount::World(_)));
    let a = world.state();
    let mut b = a.clone();
    b.task.cubes[0].position_m[1] += 0.12;
    let (img_a, img_b) = (draw(scene, &view, &a), draw(scene, &view, &b));
    assert_eq!(img_a.len(), 160 * 120 * 3);
    assert_eq!(
        img_a,
        draw(scene, &view, &a),
        "rendering is a pure function"
    );

    // The top face's centre shows the lit red.
    let top = |s: &WorldState| cube_at(s, 0) + DVec3::Z * CUBE_HALF_M;
    let pa = view.project(scene, &a, top(&a)).unwrap();
    let pb = view.project(scene, &b, top(&b)).unwrap();
    for p in [pa, pb] {
        assert!(inside(&view, (p.0, p.1)), "cube out of view at {p:?}");
    }
    let reds: Vec<[u8; 3]> = CUBE_RGB[0].to_vec();
    assert_eq!(pixel(&img_a, &view, (pa.0, pa.1)), CUBE_RGB[0][0]);
    assert_eq!(pixel(&img_b, &view, (pb.0, pb.1)), CUBE_RGB[0][0]);
    assert!(!reds.contains(&pixel(&img_b, &view, (pa.0, pa.1))));
    assert!(!reds.contains(&pixel(&img_a, &view, (pb.0, pb.1))));
    // Only the cube moved: every changed pixel lies within the cube's projected size (its
    // half-diagonal, 3.9 cm, plus a pixel) of where it was or now is.
    let changed = changed(&view, &img_a, &img_b);
    assert!(changed.len() > 10, "{} pixels changed", changed.len());
    for (x, y) in changed {
        let near = [(&a, pa), (&b, pb)].iter().any(|(s, _)| {
            let (px, py, depth) = view.project(scene, s, cube_at(s, 0)).unwrap();
            (x - px).hypot(y - py) <= view.f_px * 0.039 / (depth - 0.04) + 1.5
        });
        assert!(near, "pixel ({x}, {y}) changed, away from the cube");
    }
}

#[test]
fn the_target_marker_is_drawn_on_the_table_and_follows_the_seed() {
    let rig = rig();
    for seed in [1, 2] {
        let world = World::new(&rig, seed);
        let state = world.state();
        let view = View::for_camera(world.scene(), &rig.cameras[0], 0);
        let img = draw(world.scene(), &view, &state);
        let t = DVec3::from_array(state.task.cubes[0].target_m);
        let p = view.project(world.scene(), &state, t).unwrap();
        assert!(inside(&view, (p.0, p.1)));
        assert_eq!(
            pixel(&img, &view, (p.0, p.1)),
            TARGET_RGB[0][0],
            "seed {seed}"
        );
        let greens = (0..view.width * view.height)
            .filter(|i| img[i * 3..i * 3 + 3] == TARGET_RGB[0][0])
            .count();
        assert!(greens > 15, "seed {seed}: only {greens} marker pixels");
    }
}

#[test]
fn the_gripper_opening_is_drawn_at_the_fingers() {
    let rig = rig();
    let world = World::new(&rig, 1);
    let scene = world.scene();
    let view = View::for_camera(scene, &rig.cameras[0], 0);
    let open = world.state();
    assert!(open.arms[0].gripper_width_m > 0.07);
    let mut closed = open.clone();
    closed.arms[0].gripper_width_m = 0.0;
    let changed = changed(
        &view,
        &draw(scene, &view, &open),
        &draw(scene, &view, &closed),
    );
    assert!(!changed.is_empty(), "the gripper opening is not drawn");
    // The fingers run from the palm (5 cm behind the fingertips) to the fingertips, ± (width /
    // 2 + 8 mm) along the fingertip y axis: every changed pixel is within the box of those
    // points (finger radius 6 mm, palm radius 1 cm, a pixel of rounding).
    let layout = &scene.arms()[0];
    let tcp = layout.world_from_fingertips(&open.arms[0].q);
    let (o, y_axis, z_axis) = (
        tcp.w_axis.truncate(),
        tcp.y_axis.truncate(),
        tcp.z_axis.truncate(),
    );
    let mut corners = Vec::new();
    for end in [o, o - z_axis * 0.05] {
        for off in [-0.048, 0.048, -0.008, 0.008] {
            corners.push(view.project(scene, &open, end + y_axis * off).unwrap());
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
fn the_wrist_camera_moves_with_the_arm_and_sees_the_cube_from_above() {
    let rig = rig();
    let mut world = World::new(&rig, 1);
    let scene = world.scene().clone();
    let front = View::for_camera(&scene, &rig.cameras[0], 0);
    let wrist = View::for_camera(&scene, &rig.cameras[1], 1);
    assert!(matches!(wrist.mount, Mount::Wrist { arm: 0, .. }));
    let a = world.state();
    // Lower the fingertips to 12 cm above the cube.
    let layout = &scene.arms()[0];
    let above = cube_at(&a, 0) + DVec3::Z * 0.12;
    let tcp = layout.world_from_base.inverse()
        * DMat4::from_translation(above)
        * DMat4::from_mat3(layout.grasp_rotation)
        * layout.fingertips_from_tcp();
    let cmd = crate::world::ArmCommand {
        pose: Some(tcp),
        ..Default::default()
    };
    for _ in 0..300 {
        world.step(0.01, std::slice::from_ref(&cmd));
    }
    let b = world.state();
    assert_ne!(a.arms[0].q, b.arms[0].q);
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
    let p = wrist.project(&scene, &b, cube_at(&b, 0)).unwrap();
    assert!(
        inside(&wrist, (p.0, p.1)),
        "cube out of the wrist view: {p:?}"
    );
    let img = draw(&scene, &wrist, &b);
    let red = (0..wrist.width * wrist.height)
        .filter(|i| CUBE_RGB[0].contains(&[img[i * 3], img[i * 3 + 1], img[i * 3 + 2]]))
        .count() as f64;
    assert!(red > 0.01 * n, "the cube covers {red} of {n} wrist pixels");
}

#[test]
fn every_encoding_holds_the_same_picture() {
    let rig = rig();
    let world = World::new(&rig, 2);
    let scene = world.scene();
    let view = View::for_camera(scene, &rig.cameras[0], 0);
    let state = world.state();
    let encode = |encoding: &str| {
        let mut out = Vec::new();
        render(scene, &view, &state, encoding, &mut out);
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
                _ => {
                    vec![((u16::from(r) * 77 + u16::from(g) * 150 + u16::from(b) * 29) >> 8) as u8]
                }
            };
            assert_eq!(px, want, "{encoding}");
        }
    }
}

/// A rig's `vertical_fov_deg` sets the focal length: half the height over the tangent of half
/// the field.
#[test]
fn a_vertical_field_of_view_sets_the_focal_length() {
    let mut rig = rig();
    rig.cameras[1].vertical_fov_deg = Some(40.0);
    let scene = Scene::new(&rig);
    let zoomed = View::for_camera(&scene, &rig.cameras[1], 1);
    let want = 60.0 / 20f64.to_radians().tan();
    assert!(
        (zoomed.f_px - want).abs() < 1e-9,
        "{} vs {want}",
        zoomed.f_px
    );
    rig.cameras[1].vertical_fov_deg = None;
    let own = View::for_camera(&scene, &rig.cameras[1], 1);
    assert!(own.f_px < zoomed.f_px, "{} vs {}", own.f_px, zoomed.f_px);
}
