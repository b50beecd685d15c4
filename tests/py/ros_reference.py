"""Reference ros2msg texts and CDR bytes from Python `rosbags` (what rosbag2 writes).

Prints JSON: {"definitions": {type: text}, "cdr": {name: {"le": hex, "be": hex}}}.
The Rust tests build the same messages and compare byte for byte.
"""
import json

import numpy as np
from rosbags.typesys import Stores, get_typestore

ts = get_typestore(Stores.ROS2_HUMBLE)
TYPES = [
    "builtin_interfaces/msg/Time",
    "std_msgs/msg/Header",
    "sensor_msgs/msg/Image",
    "sensor_msgs/msg/CompressedImage",
    "sensor_msgs/msg/JointState",
    "geometry_msgs/msg/Point",
    "geometry_msgs/msg/Quaternion",
    "geometry_msgs/msg/Pose",
    "geometry_msgs/msg/PoseStamped",
    "sensor_msgs/msg/CameraInfo",
    "tf2_msgs/msg/TFMessage",
]

Time = ts.types["builtin_interfaces/msg/Time"]
Header = ts.types["std_msgs/msg/Header"]
header = Header(stamp=Time(sec=1700000000, nanosec=123456789), frame_id="zed_front_camera_optical_frame")
P = ts.types["geometry_msgs/msg/Point"]
Q = ts.types["geometry_msgs/msg/Quaternion"]
samples = {
    "image": ("sensor_msgs/msg/Image", ts.types["sensor_msgs/msg/Image"](
        header=header, height=2, width=3, encoding="bgra8", is_bigendian=0, step=12,
        data=np.arange(24, dtype=np.uint8))),
    "compressed": ("sensor_msgs/msg/CompressedImage", ts.types["sensor_msgs/msg/CompressedImage"](
        header=header, format="jpeg", data=np.array([255, 216, 255, 217], dtype=np.uint8))),
    "joint_state": ("sensor_msgs/msg/JointState", ts.types["sensor_msgs/msg/JointState"](
        header=header, name=["fr3_joint1", "fr3_joint2", "j"],
        position=np.array([0.5, -1.25, 3.0]), velocity=np.array([0.0, 0.1, -0.2]), effort=np.array([], dtype=np.float64))),
    "pose_stamped": ("geometry_msgs/msg/PoseStamped", ts.types["geometry_msgs/msg/PoseStamped"](
        header=header, pose=ts.types["geometry_msgs/msg/Pose"](
            position=P(x=0.1, y=-0.2, z=0.3), orientation=Q(x=0.0, y=0.0, z=0.7071067811865476, w=0.7071067811865476)))),
    "camera_info": ("sensor_msgs/msg/CameraInfo", ts.types["sensor_msgs/msg/CameraInfo"](
        header=header, height=480, width=640, distortion_model="plumb_bob",
        d=np.array([0.1, -0.2, 0.0, 0.001, 0.05]),
        k=np.array([600.5, 0.0, 320.0, 0.0, 600.5, 240.0, 0.0, 0.0, 1.0]),
        r=np.array([1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]),
        p=np.array([600.5, 0.0, 320.0, 0.0, 0.0, 600.5, 240.0, 0.0, 0.0, 0.0, 1.0, 0.0]),
        binning_x=2, binning_y=0,
        roi=ts.types["sensor_msgs/msg/RegionOfInterest"](x_offset=1, y_offset=2, height=3, width=4, do_rectify=True))),
    "tf": ("tf2_msgs/msg/TFMessage", ts.types["tf2_msgs/msg/TFMessage"](transforms=[
        ts.types["geometry_msgs/msg/TransformStamped"](
            header=header, child_frame_id="fr3_link0",
            transform=ts.types["geometry_msgs/msg/Transform"](
                translation=ts.types["geometry_msgs/msg/Vector3"](x=0.25, y=-0.5, z=2.0),
                rotation=Q(x=0.0, y=0.0, z=0.7071067811865476, w=0.7071067811865476))),
        ts.types["geometry_msgs/msg/TransformStamped"](
            header=Header(stamp=Time(sec=1, nanosec=2), frame_id=""), child_frame_id="cam",
            transform=ts.types["geometry_msgs/msg/Transform"](
                translation=ts.types["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
                rotation=Q(x=0.0, y=0.0, z=0.0, w=1.0))),
    ])),
}

out = {
    "definitions": {t: ts.generate_msgdef(t, ros_version=2)[0] for t in TYPES},
    "cdr": {
        name: {
            "le": bytes(ts.serialize_cdr(msg, t, little_endian=True)).hex(),
            "be": bytes(ts.serialize_cdr(msg, t, little_endian=False)).hex(),
        }
        for name, (t, msg) in samples.items()
    },
}
print(json.dumps(out))
