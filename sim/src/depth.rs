//! What a camera's depth sensor and its driver's `camera_info` would say, from the same view the
//! colour image is rendered from: registered depth (the renderer has no z-buffer, so it is the
//! table plane's distance along the optical axis: unknown where a ray misses the table or lies
//! beyond the sensor's range, as real depth is) in the rig's encoding, and a pinhole
//! `camera_info` whose K is the renderer's own projection.

use scaledp_schema::msg::{CameraInfo, Header, Image, Time};
use scaledp_schema::rig::{Camera, DepthEncoding};
use scaledp_schema::RosMessage;

use crate::render::{Mount, View};
use crate::scene::{Scene, TABLE_Z_M};
use crate::world::WorldState;

/// Farther than this (m) a depth sensor reports nothing (a ZED's range is ~20 m, a D435's ~10 m;
/// the cell's wall is out of it).
const MAX_RANGE_M: f64 = 10.0;

/// The optical frame of a camera, as its images' headers name it.
pub fn optical_frame(cam: &Camera) -> String {
    format!("{}_camera_optical_frame", cam.name)
}

/// A camera's depth images: the pixels of a fixed camera are the same every frame and are
/// computed once; a wrist camera's follow the arm.
pub(crate) struct DepthSensor {
    encoding: DepthEncoding,
    fixed: Option<Vec<u8>>,
}

impl DepthSensor {
    pub fn new(encoding: DepthEncoding) -> Self {
        Self {
            encoding,
            fixed: None,
        }
    }

    /// The `sensor_msgs/Image` payload of the depth seen by `view` in `state`, stamped
    /// `stamp_ns`.
    pub fn message(
        &mut self,
        cam: &Camera,
        scene: &Scene,
        view: &View,
        state: &WorldState,
        stamp_ns: u64,
    ) -> Vec<u8> {
        let data = match (&self.fixed, view.mount()) {
            (Some(d), _) => d.clone(),
            (None, Mount::World(_)) => {
                let d = depth_pixels(scene, view, state, self.encoding);
                self.fixed = Some(d.clone());
                d
            }
            (None, Mount::Wrist { .. }) => depth_pixels(scene, view, state, self.encoding),
        };
        let (w, _) = view.size();
        Image {
            header: Header {
                stamp: Time::from_ns(stamp_ns),
                frame_id: optical_frame(cam),
            },
            height: cam.height,
            width: cam.width,
            encoding: self.encoding.as_str().into(),
            is_bigendian: 0,
            step: (w * self.encoding.bytes_per_pixel()) as u32,
            data,
        }
        .to_cdr()
    }
}

/// Row-major little-endian depth of the table plane as `view` sees it: millimetres (0 unknown)
/// or metres (NaN unknown).
pub fn depth_pixels(
    scene: &Scene,
    view: &View,
    state: &WorldState,
    encoding: DepthEncoding,
) -> Vec<u8> {
    let world_from_camera = view.world_from_camera(scene, state);
    let eye = world_from_camera.w_axis.truncate();
    let (f, cx, cy) = view.intrinsics();
    let (w, h) = view.size();
    let mut out = Vec::with_capacity(w * h * encoding.bytes_per_pixel());
    for y in 0..h {
        for x in 0..w {
            let ray = glam::DVec3::new((x as f64 + 0.5 - cx) / f, (y as f64 + 0.5 - cy) / f, 1.0);
            let d = world_from_camera.transform_vector3(ray);
            // Along the ray scaled to z = 1 in the camera, t is the optical-axis depth.
            let t = if d.z < -1e-9 {
                (TABLE_Z_M - eye.z) / d.z
            } else {
                f64::INFINITY
            };
            let known = t > 0.0 && t <= MAX_RANGE_M;
            match encoding {
                DepthEncoding::U16Millimetres => {
                    let mm = if known {
                        (t * 1000.0).round() as u16
                    } else {
                        0
                    };
                    out.extend_from_slice(&mm.to_le_bytes());
                }
                DepthEncoding::F32Metres => {
                    let m = if known { t as f32 } else { f32::NAN };
                    out.extend_from_slice(&m.to_le_bytes());
                }
            }
        }
    }
    out
}

/// The driver's `camera_info` for the images `view` renders: pinhole K from the renderer's
/// focal length and principal point, no distortion (the images are rectified).
pub fn camera_info(cam: &Camera, view: &View, stamp_ns: u64) -> CameraInfo {
    let (f, cx, cy) = view.intrinsics();
    let header = Header {
        stamp: Time::from_ns(stamp_ns),
        frame_id: optical_frame(cam),
    };
    CameraInfo::pinhole(header, cam.width, cam.height, f, cx, cy)
}

#[cfg(test)]
mod tests {
    use scaledp_schema::Rig;

    use super::*;
    use crate::world::World;

    #[test]
    fn depth_is_the_table_where_the_camera_sees_it_and_k_projects_like_the_renderer() {
        let rig = Rig::builtin("franka_2zed").unwrap().with_image_size(64, 48);
        let scene = std::sync::Arc::new(Scene::new(&rig));
        let state = World::with_scene(scene.clone(), 0).state();
        let cam = &rig.cameras[0];
        let view = View::for_camera(&scene, cam, 0);
        let mm = depth_pixels(&scene, &view, &state, DepthEncoding::U16Millimetres);
        let m = depth_pixels(&scene, &view, &state, DepthEncoding::F32Metres);
        assert_eq!((mm.len(), m.len()), (64 * 48 * 2, 64 * 48 * 4));
        let at_mm = |x: usize, y: usize| {
            u16::from_le_bytes([mm[2 * (y * 64 + x)], mm[2 * (y * 64 + x) + 1]])
        };
        let at_m = |x: usize, y: usize| {
            let i = 4 * (y * 64 + x);
            f32::from_le_bytes([m[i], m[i + 1], m[i + 2], m[i + 3]])
        };
        // The front camera looks down at the table: the bottom row is nearer than the middle,
        // both plausible (tens of cm to a few m); the two encodings agree.
        let (near, mid) = (at_mm(32, 47), at_mm(32, 24));
        assert!(200 < near && near < mid && mid < 4000, "{near} {mid}");
        assert!((f64::from(at_m(32, 24)) * 1000.0 - f64::from(mid)).abs() <= 1.0);
        // K maps the table point under the principal point back onto that pixel.
        let info = camera_info(cam, &view, 7);
        let (f, cx, cy) = view.intrinsics();
        assert_eq!(info.k, [f, 0.0, cx, 0.0, f, cy, 0.0, 0.0, 1.0]);
        assert_eq!((info.width, info.height), (64, 48));
        assert_eq!(info.header.frame_id, "front_camera_optical_frame");
        let mut sensor = DepthSensor::new(DepthEncoding::F32Metres);
        let msg = Image::from_cdr(&sensor.message(cam, &scene, &view, &state, 9)).unwrap();
        assert_eq!(
            (msg.encoding.as_str(), msg.step, msg.data.len()),
            ("32FC1", 256, 64 * 48 * 4)
        );
    }
}
