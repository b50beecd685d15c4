//! Observations built live exactly as the converter built the training data, for a deployment
//! node (`scaledp serve`) that must use the same alignment rule, the same kinematics and the
//! same image path as `scaledp convert`, or the policy sees inputs it was never trained on.
//!
//! At each control tick `t` (ns, on the same clock as the header stamps — or receive times if
//! the dataset was converted with `--log-time`):
//!
//! - **Cameras**: [`frame_at`] picks each camera's latest frame stamped at or before `t`, and
//!   says whether it is fresh (at most `stale_periods` frame periods old; the converter's
//!   default is 1.5, `--stale-periods`). The frame goes through [`encode_frame`]: decoded
//!   (raw `sensor_msgs/Image` in bgra8/bgr8/rgb8/rgba8/mono8 honouring `step`, or a JPEG/PNG
//!   `CompressedImage`; CDR or ROS 1), resized with Lanczos3 to the dataset's size and
//!   JPEG-encoded at its quality — the very bytes the dataset stores for such a frame. Decode
//!   them as the loader does (`scaledp_datasets::decode_image`) to get the policy's input.
//! - **Joints**: [`joints_at`] interpolates an arm's (or gripper's) positions linearly between
//!   the samples around `t`, refusing a hole wider than ten periods (and 50 ms). It needs a
//!   sample after `t`: a live node runs its ticks one joint period behind the newest sample.
//! - **State**: [`ArmKinematics::tcp_pose`] turns an arm's joint positions into its TCP pose
//!   `[x, y, z, roll, pitch, yaw]` in the base frame (built-in model or the rig's URDF chain,
//!   then its TCP offset); consecutive poses are put on one branch with
//!   [`unwrap_angles`] (the converter unwraps along the episode: unwrap the new pose against
//!   the previous one); the gripper's opening is
//!   [`scaledp_schema::rig::GripperModel::width_m`] of its interpolated joints. Per arm in rig
//!   order, `x, y, z, roll, pitch, yaw, gripper` (see [`crate::episode::state_names`]), as
//!   float32.

use std::path::Path;

pub use crate::images::EncodeSpec;
pub use crate::kinematics::ArmKinematics;
pub use scaledp_schema::kinematics::unwrap_angles;

use crate::error::Result;
use crate::source::Serialization;

/// The converter's frame rule at tick `t_ns`: the index of the latest of a camera's frame
/// stamps (`stamps_ns`, ascending) at or before the tick, and whether it is fresh — no older
/// than `stale_periods` × `period_s` (the camera's nominal frame period, 1 / its rig `fps`).
/// `None` when no frame is at or before the tick.
pub fn frame_at(
    stamps_ns: &[u64],
    period_s: f64,
    t_ns: u64,
    stale_periods: f64,
) -> Option<(usize, bool)> {
    scaledp_align::latest_at(stamps_ns, t_ns)?;
    Some(scaledp_align::frame_at(
        stamps_ns,
        period_s,
        t_ns,
        stale_periods,
    ))
}

/// The converter's joint rule at tick `t_ns`: positions (`positions[i]` stamped `stamps_ns[i]`,
/// ascending; `period_s` the stream's nominal period, 1 / its rig `rate_hz`) linearly
/// interpolated between the samples around the tick. `None` without a sample at or after the
/// tick, or across a hole wider than [`max_hole_s`](scaledp_align::max_hole_s) (ten periods,
/// 50 ms or one tick of `tick_s`, whichever is widest).
pub fn joints_at(
    stamps_ns: &[u64],
    positions: &[Vec<f64>],
    period_s: f64,
    tick_s: f64,
    t_ns: u64,
) -> Option<Vec<f64>> {
    scaledp_align::bracket(stamps_ns, t_ns)?;
    let ((i, j, w), sound) = scaledp_align::sample_at(stamps_ns, period_s, t_ns, tick_s);
    let (a, b) = (positions.get(i)?, positions.get(j)?);
    sound.then(|| crate::kinematics::lerp(a, b, w))
}

/// The converter's image path: one camera message (`sensor_msgs/msg/Image` or
/// `sensor_msgs/msg/CompressedImage`, serialized as `serialization`) decoded, resized with
/// Lanczos3 to `spec`'s size and JPEG-encoded at its quality. Equal to what the dataset stores
/// for the same message.
pub fn encode_frame(
    message_type: &str,
    serialization: Serialization,
    data: &[u8],
    spec: &EncodeSpec,
) -> Result<Vec<u8>> {
    let path = Path::new("live");
    crate::images::encode_message(path, "camera", message_type, 0, serialization, data, spec)
        .map(|e| e.bytes)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::episode::convert;
    use crate::frames::InMemory;
    use crate::options::ConvertOptions;
    use crate::source::{RawMessage, Recording};
    use scaledp_schema::msg::{Header, Image, JointState, Time};
    use scaledp_schema::{Rig, RosMessage};

    const T0: u64 = 1_700_000_000_000_000_000;

    /// One camera (rgb8 48×32, 30 Hz) and one FR3 arm (250 Hz) with gripper (50 Hz), 2 s, stamps
    /// jittered; each frame a different picture.
    fn recording(rig: &Rig) -> Recording {
        let mut messages = Vec::new();
        let cam = &rig.cameras[0];
        let arm = &rig.arms[0];
        let gripper = arm.gripper.as_ref().unwrap();
        let header = |ns: u64| Header {
            stamp: Time::from_ns(ns),
            frame_id: String::new(),
        };
        for k in 0..60u64 {
            let ns = T0 + k * 33_333_333 + (k * 7919 % 500_000);
            let img = Image {
                header: header(ns),
                height: 32,
                width: 48,
                encoding: "rgb8".into(),
                is_bigendian: 0,
                step: 48 * 3,
                data: (0..48 * 32 * 3)
                    .map(|i| ((i as u64 * 31 + k * 17) % 251) as u8)
                    .collect(),
            };
            messages.push(RawMessage {
                topic: cam.topic.clone(),
                message_type: "sensor_msgs/msg/Image".into(),
                log_time_ns: ns + 20_000_000,
                data: img.to_cdr(),
                serialization: Serialization::Cdr,
            });
        }
        for (topic, names, hz) in [
            (&arm.joint_state_topic, &arm.joint_names, 250u64),
            (&gripper.topic, &gripper.joint_names, 50),
        ] {
            for k in 0..2 * hz {
                let ns = T0 + k * 1_000_000_000 / hz + (k * 104_729 % 300_000);
                let t = (ns - T0) as f64 * 1e-9;
                let js = JointState {
                    header: header(ns),
                    name: names.clone(),
                    position: (0..names.len())
                        .map(|j| 0.02 + 0.01 * (t * (1.0 + j as f64)).sin() + j as f64 * 0.1)
                        .collect(),
                    velocity: vec![],
                    effort: vec![],
                };
                messages.push(RawMessage {
                    topic: topic.clone(),
                    message_type: "sensor_msgs/msg/JointState".into(),
                    log_time_ns: ns + 500_000,
                    data: js.to_cdr(),
                    serialization: Serialization::Cdr,
                });
            }
        }
        messages.sort_by_key(|m| m.log_time_ns);
        Recording {
            messages,
            ..Recording::default()
        }
    }

    #[test]
    fn a_live_observation_equals_what_the_converter_stored_for_that_tick() {
        let mut rig = Rig::builtin("franka_2zed").unwrap();
        rig.cameras.truncate(1);
        // Colour and joints only: what a policy observes live.
        rig.cameras[0].depth = None;
        let rec = recording(&rig);
        let opts = ConvertOptions::default()
            .rig(rig.clone())
            .task("t")
            .size(40, 30)
            .jpeg_quality(85);
        let ep = convert(Path::new("x.mcap"), &rec, &InMemory(&rec), &opts).unwrap();
        assert!(ep.len() > 10);

        // What a live node has buffered: stamps and messages per topic.
        let of = |topic: &str| -> Vec<&RawMessage> {
            rec.messages.iter().filter(|m| m.topic == topic).collect()
        };
        let cam = &rig.cameras[0];
        let frames = of(&cam.topic);
        let frame_stamps: Vec<u64> = frames
            .iter()
            .map(|m| Image::from_cdr(&m.data).unwrap().header.stamp.as_ns())
            .collect();
        let series = |topic: &str| -> (Vec<u64>, Vec<Vec<f64>>) {
            of(topic)
                .iter()
                .map(|m| {
                    let js = JointState::from_cdr(&m.data).unwrap();
                    (js.header.stamp.as_ns(), js.position)
                })
                .unzip()
        };
        let arm = &rig.arms[0];
        let gripper = arm.gripper.as_ref().unwrap();
        let (arm_stamps, arm_q) = series(&arm.joint_state_topic);
        let (grip_stamps, grip_q) = series(&gripper.topic);
        let kin = ArmKinematics::new(arm).unwrap();
        let spec = EncodeSpec {
            width: 40,
            height: 30,
            quality: 85,
            raw: false,
        };
        // The ticks, on the converter's grid (`align::first_tick` from the streams' first
        // stamps), from the first one the episode kept (invalid ticks at the start are trimmed).
        let step = 1e9 / rig.control_rate_hz;
        let start = frame_stamps[0].max(arm_stamps[0]).max(grip_stamps[0]);
        let origin = scaledp_align::first_tick(start, Some(frame_stamps[0]), 1.0 / cam.fps, step);
        let tick = |k: usize| origin + (k as f64 * step).round() as u64;
        let first_joints = &ep.joints[..arm.joint_names.len()];
        let trimmed = (0..10)
            .find(|&k| {
                joints_at(&arm_stamps, &arm_q, 1.0 / arm.rate_hz, step * 1e-9, tick(k)).is_some_and(
                    |q| {
                        q.iter()
                            .zip(first_joints)
                            .all(|(a, b)| (*a as f32 - b).abs() < 1e-7)
                    },
                )
            })
            .expect("the first tick kept");
        let dim = ep.state_names.len();
        let joints = ep.joint_names.len();
        let mut previous: Option<[f64; 6]> = None;
        for k in 0..ep.len() {
            let t = tick(k + trimmed);
            // Joints and state.
            let q = joints_at(&arm_stamps, &arm_q, 1.0 / arm.rate_hz, step * 1e-9, t).unwrap();
            let g =
                joints_at(&grip_stamps, &grip_q, 1.0 / gripper.rate_hz, step * 1e-9, t).unwrap();
            let stored_joints = &ep.joints[k * joints..(k + 1) * joints];
            let live_joints: Vec<f32> = q.iter().chain(&g).map(|&x| x as f32).collect();
            assert!(
                live_joints
                    .iter()
                    .zip(stored_joints)
                    .all(|(a, b)| (a - b).abs() <= 1e-6),
                "tick {k}: joints {live_joints:?} vs {stored_joints:?}"
            );
            let mut pose = kin.tcp_pose(&q).unwrap();
            if let Some(prev) = previous {
                for d in 3..6 {
                    let mut pair = [prev[d], pose[d]];
                    unwrap_angles(&mut pair);
                    pose[d] = pair[1];
                }
            }
            previous = Some(pose);
            let mut state: Vec<f32> = pose.iter().map(|&v| v as f32).collect();
            state.push(gripper.model.width_m(&g) as f32);
            let stored = &ep.state[k * dim..(k + 1) * dim];
            assert!(
                state.iter().zip(stored).all(|(a, b)| (a - b).abs() <= 1e-5),
                "tick {k}: state {state:?} vs {stored:?}"
            );
            // The frame: the same pick, the same bytes.
            let (i, fresh) = frame_at(&frame_stamps, 1.0 / cam.fps, t, 1.5).unwrap();
            assert!(fresh);
            let m = frames[i];
            let jpeg = encode_frame(&m.message_type, m.serialization, &m.data, &spec).unwrap();
            assert_eq!(jpeg, ep.cameras[0].jpeg[k], "tick {k}: frame {i}");
        }
    }

    #[test]
    fn stale_frames_and_joint_holes_are_refused() {
        let stamps = [0, 33_000_000, 66_000_000];
        assert_eq!(frame_at(&stamps, 0.033, 70_000_000, 1.5), Some((2, true)));
        assert_eq!(frame_at(&stamps, 0.033, 200_000_000, 1.5), Some((2, false)));
        assert_eq!(frame_at(&stamps, 0.033, 0, 1.5), Some((0, true)));
        let js = [0, 1_000_000, 500_000_000, 580_000_000, 700_000_000];
        let q = [vec![0.0], vec![1.0], vec![2.0], vec![3.0], vec![4.0]];
        let tick = 0.1; // 10 Hz
        assert_eq!(joints_at(&js, &q, 0.001, tick, 500_000), Some(vec![0.5]));
        assert_eq!(
            joints_at(&js, &q, 0.001, tick, 2_000_000),
            None,
            "a hole of 499 ms"
        );
        // An 80 ms hole of a 1 kHz stream: sound at 10 Hz ticks, not at 30 Hz (limit 50 ms).
        assert_eq!(
            joints_at(&js, &q, 0.001, tick, 540_000_000),
            Some(vec![2.5])
        );
        assert_eq!(joints_at(&js, &q, 0.001, 1.0 / 30.0, 540_000_000), None);
        assert_eq!(
            joints_at(&js, &q, 0.001, tick, 800_000_000),
            None,
            "nothing after the tick"
        );
    }
}
