//! Safety limits on every command: the TCP target kept inside a workspace box (in the arm's
//! base frame), moved at most `max_step_m` and turned at most `max_step_rad` per control tick
//! from the previous command, and the gripper opening kept within its range.

use glam::{DMat3, DMat4, DQuat, DVec3};
use scaledp_schema::Rig;
use scaledp_sim::scene::{Scene, TABLE_Z_M};

/// An axis-aligned box in an arm's base frame (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Workspace {
    /// Lowest x, y, z.
    pub min: DVec3,
    /// Highest x, y, z.
    pub max: DVec3,
}

impl Workspace {
    /// From `xmin,ymin,zmin,xmax,ymax,zmax`.
    pub fn parse(text: &str) -> Option<Self> {
        let v: Vec<f64> = text
            .split(',')
            .map(|s| s.trim().parse().ok())
            .collect::<Option<_>>()?;
        let [a, b, c, d, e, f] = v.as_slice().try_into().ok()?;
        let ws = Workspace {
            min: DVec3::new(a, b, c),
            max: DVec3::new(d, e, f),
        };
        (ws.min.is_finite() && ws.max.is_finite() && ws.min.cmple(ws.max).all()).then_some(ws)
    }

    /// The box of each arm of `rig`: the rig's own (`workspace` of every arm), else the arm's
    /// box in its simulated cell: the patch of table its cube and target are drawn from, 12 cm
    /// wider each way, from 5 mm above the table to 45 cm above it, in the arm's base frame.
    pub fn for_rig(rig: &Rig) -> Vec<Workspace> {
        // A rig that states its boxes (a benchmark's simulator) is taken at its word.
        if rig.arms.iter().all(|a| a.workspace.is_some()) {
            return rig
                .arms
                .iter()
                .filter_map(|a| a.workspace)
                .map(|w| Workspace {
                    min: DVec3::new(w[0], w[1], w[2]),
                    max: DVec3::new(w[3], w[4], w[5]),
                })
                .collect();
        }
        let scene = Scene::new(rig);
        scene
            .arms()
            .iter()
            .map(|a| {
                let half = a.region_half + glam::DVec2::splat(0.12);
                let base_from_world = a.world_from_base.inverse();
                let (mut min, mut max) = (DVec3::splat(f64::MAX), DVec3::splat(f64::MIN));
                for sx in [-1.0, 1.0] {
                    for sy in [-1.0, 1.0] {
                        for z in [TABLE_Z_M + 0.005, TABLE_Z_M + 0.45] {
                            let w = a.region_center.truncate() + half * glam::DVec2::new(sx, sy);
                            let p = base_from_world.transform_point3(w.extend(z));
                            min = min.min(p);
                            max = max.max(p);
                        }
                    }
                }
                Workspace { min, max }
            })
            .collect()
    }

    /// True when `p` lies inside (within 1 µm).
    pub fn contains(&self, p: DVec3) -> bool {
        p.cmpge(self.min - 1e-6).all() && p.cmple(self.max + 1e-6).all()
    }
}

/// Per-tick limits.
#[derive(Debug, Clone, PartialEq)]
pub struct Limits {
    /// One box per arm (rig order).
    pub workspace: Vec<Workspace>,
    /// Largest TCP translation per control tick (m).
    pub max_step_m: f64,
    /// Largest TCP rotation per control tick (rad).
    pub max_step_rad: f64,
}

/// What clamping did to one command.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Clamped {
    /// The target lay outside the workspace box.
    pub workspace: bool,
    /// The step from the previous command was too long or turned too far.
    pub step: bool,
    /// The gripper opening was out of range.
    pub gripper: bool,
}

impl Clamped {
    /// Anything clamped.
    pub fn any(&self) -> bool {
        self.workspace || self.step || self.gripper
    }
}

/// `target` (`base_from_tcp`) limited to `ws` and to one step from `previous`; the rotation
/// re-orthonormalized.
pub fn clamp_pose(
    target: DMat4,
    previous: DMat4,
    ws: &Workspace,
    limits: &Limits,
    clamped: &mut Clamped,
) -> DMat4 {
    let mut p = target.w_axis.truncate();
    let boxed = p.clamp(ws.min, ws.max);
    clamped.workspace |= boxed != p;
    p = boxed;
    let prev_p = previous.w_axis.truncate();
    let d = p - prev_p;
    if d.length() > limits.max_step_m {
        p = prev_p + d * (limits.max_step_m / d.length());
        clamped.step = true;
    }
    let q_prev = DQuat::from_mat3(&DMat3::from_mat4(previous)).normalize();
    let mut q = DQuat::from_mat3(&DMat3::from_mat4(target)).normalize();
    let angle = q_prev.angle_between(q);
    if angle > limits.max_step_rad {
        q = q_prev.slerp(q, limits.max_step_rad / angle).normalize();
        clamped.step = true;
    }
    DMat4::from_rotation_translation(q, p)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn targets_stay_in_the_box_and_within_one_step() {
        let ws = Workspace::parse("0.2,-0.3,0.0,0.7,0.3,0.5").unwrap();
        let limits = Limits {
            workspace: vec![ws],
            max_step_m: 0.05,
            max_step_rad: 0.1,
        };
        let prev = DMat4::from_translation(DVec3::new(0.4, 0.0, 0.2));
        let far = DMat4::from_translation(DVec3::new(5.0, 0.0, -1.0)) * DMat4::from_rotation_x(1.0);
        let mut c = Clamped::default();
        let out = clamp_pose(far, prev, &ws, &limits, &mut c);
        assert!(c.workspace && c.step);
        let p = out.w_axis.truncate();
        assert!(ws.contains(p));
        assert!((p - DVec3::new(0.4, 0.0, 0.2)).length() <= 0.05 + 1e-12);
        let turned = DQuat::from_mat3(&DMat3::from_mat4(out)).angle_between(DQuat::IDENTITY);
        assert!((turned - 0.1).abs() < 1e-9, "{turned}");
        let mut c = Clamped::default();
        let near = DMat4::from_translation(DVec3::new(0.42, 0.01, 0.2));
        let out = clamp_pose(near, prev, &ws, &limits, &mut c);
        assert!(!c.any());
        assert!(out.abs_diff_eq(near, 1e-12));
        assert_eq!(Workspace::parse("1,2,3"), None);
        assert_eq!(Workspace::parse("1,0,0,0,1,1"), None, "min above max");
    }

    #[test]
    fn the_sim_boxes_hold_each_arms_cubes() {
        let rig = Rig::builtin("franka_sim").unwrap();
        let ws = Workspace::for_rig(&rig);
        let scene = Scene::new(&rig);
        let a = &scene.arms()[0];
        let centre = a
            .world_from_base
            .inverse()
            .transform_point3(a.region_center + DVec3::Z * 0.05);
        assert!(ws[0].contains(centre), "{ws:?} vs {centre}");
        assert!(!ws[0].contains(centre + DVec3::Z * 1.0));
    }
}
