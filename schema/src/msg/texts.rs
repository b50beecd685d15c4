//! The `.msg` texts of every type scaledp knows and their composition into rosbag2's `ros2msg`
//! schema text.

/// `.msg` text and direct dependencies of every type this crate knows, keyed by `pkg/Type`
/// (the comment-free texts Python `rosbags` generates for ROS 2 Humble).
const DEFS: &[(&str, &str, &[&str])] = &[
    ("builtin_interfaces/Time", "int32 sec\nuint32 nanosec\n", &[]),
    (
        "std_msgs/Header",
        "builtin_interfaces/Time stamp\nstring frame_id\n",
        &["builtin_interfaces/Time"],
    ),
    (
        "sensor_msgs/Image",
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\nuint32 step\nuint8[] data\n",
        &["std_msgs/Header"],
    ),
    (
        "sensor_msgs/CompressedImage",
        "std_msgs/Header header\nstring format\nuint8[] data\n",
        &["std_msgs/Header"],
    ),
    (
        "sensor_msgs/JointState",
        "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\nfloat64[] effort\n",
        &["std_msgs/Header"],
    ),
    (
        "sensor_msgs/RegionOfInterest",
        "uint32 x_offset\nuint32 y_offset\nuint32 height\nuint32 width\nbool do_rectify\n",
        &[],
    ),
    (
        "sensor_msgs/CameraInfo",
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring distortion_model\nfloat64[] d\nfloat64[9] k\nfloat64[9] r\nfloat64[12] p\nuint32 binning_x\nuint32 binning_y\nsensor_msgs/RegionOfInterest roi\n",
        &["std_msgs/Header", "sensor_msgs/RegionOfInterest"],
    ),
    (
        "foxglove_msgs/CompressedVideo",
        "builtin_interfaces/Time timestamp\nstring frame_id\nuint8[] data\nstring format\n",
        &["builtin_interfaces/Time"],
    ),
    (
        "rosgraph_msgs/Clock",
        "builtin_interfaces/Time clock\n",
        &["builtin_interfaces/Time"],
    ),
    ("geometry_msgs/Point", "float64 x\nfloat64 y\nfloat64 z\n", &[]),
    ("geometry_msgs/Vector3", "float64 x\nfloat64 y\nfloat64 z\n", &[]),
    ("geometry_msgs/Quaternion", "float64 x\nfloat64 y\nfloat64 z\nfloat64 w\n", &[]),
    (
        "geometry_msgs/Pose",
        "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n",
        &["geometry_msgs/Point", "geometry_msgs/Quaternion"],
    ),
    (
        "geometry_msgs/PoseStamped",
        "std_msgs/Header header\ngeometry_msgs/Pose pose\n",
        &["std_msgs/Header", "geometry_msgs/Pose"],
    ),
    (
        "geometry_msgs/Transform",
        "geometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n",
        &["geometry_msgs/Vector3", "geometry_msgs/Quaternion"],
    ),
    (
        "geometry_msgs/TransformStamped",
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform\n",
        &["std_msgs/Header", "geometry_msgs/Transform"],
    ),
    (
        "tf2_msgs/TFMessage",
        "geometry_msgs/TransformStamped[] transforms\n",
        &["geometry_msgs/TransformStamped"],
    ),
];

/// `sensor_msgs/msg/Image` or `sensor_msgs/Image` → `sensor_msgs/Image`.
pub(super) fn short_name(type_name: &str) -> String {
    type_name.replacen("/msg/", "/", 1)
}

/// The `.msg` text of a known type (no dependencies), by either spelling of its name.
pub(super) fn own_text(type_name: &str) -> Option<&'static str> {
    let short = short_name(type_name);
    DEFS.iter()
        .find(|(n, _, _)| *n == short)
        .map(|(_, t, _)| *t)
}

/// The full names (`pkg/msg/Type`) of every type [`definition`] knows.
pub fn known_types() -> impl Iterator<Item = String> {
    DEFS.iter().map(|(n, _, _)| n.replacen('/', "/msg/", 1))
}

/// The `ros2msg` definition of a known type (`sensor_msgs/msg/Image` or `sensor_msgs/Image`).
pub fn definition(type_name: &str) -> Option<String> {
    let short = short_name(type_name);
    let lookup = |name: &str| DEFS.iter().find(|(n, _, _)| *n == name);
    let (_, root, deps) = lookup(&short)?;
    let mut order: Vec<&str> = Vec::new();
    fn visit<'a>(deps: &[&'a str], order: &mut Vec<&'a str>) {
        for d in deps {
            if !order.contains(d) {
                order.push(d);
                if let Some((_, _, sub)) = DEFS.iter().find(|(n, _, _)| n == d) {
                    visit(sub, order);
                }
            }
        }
    }
    visit(deps, &mut order);
    let mut out = root.to_string();
    for dep in order {
        let (_, text, _) = lookup(dep)?;
        // Every text ends in '\n', so each separator starts on a line of its own.
        out.push_str(&"=".repeat(80));
        out.push_str("\nMSG: ");
        out.push_str(dep);
        out.push('\n');
        out.push_str(text);
    }
    Some(out)
}
