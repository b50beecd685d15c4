//! Whether two rigs' cameras see alike. A simulated camera's field of view (`vertical_fov_deg`)
//! changes every picture without changing a topic, a size or an encoding, so a dataset, a
//! checkpoint and a benchmark run compare it explicitly before mixing pictures.

use crate::rig::Rig;

/// A camera both rigs have by name, at different vertical fields of view.
#[derive(Debug, Clone, PartialEq)]
pub struct FovChange {
    /// The camera's name.
    pub camera: String,
    /// Its field in the first rig (`None`: the simulator's own).
    pub from: Option<f64>,
    /// Its field in the second rig.
    pub to: Option<f64>,
}

/// `45°`, or `the simulator's own` for a camera the rig does not zoom.
pub fn fov_label(fov: Option<f64>) -> String {
    match fov {
        Some(d) => format!("{d}°"),
        None => "the simulator's own".to_string(),
    }
}

impl std::fmt::Display for FovChange {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "camera {} has a vertical field of view of {}, not {}",
            self.camera,
            fov_label(self.to),
            fov_label(self.from)
        )
    }
}

impl Rig {
    /// The first camera of `self` that `other` has by name at another vertical field of view.
    pub fn fov_change(&self, other: &Rig) -> Option<FovChange> {
        self.cameras.iter().find_map(|a| {
            let b = other.cameras.iter().find(|b| b.name == a.name)?;
            (a.vertical_fov_deg != b.vertical_fov_deg).then(|| FovChange {
                camera: a.name.clone(),
                from: a.vertical_fov_deg,
                to: b.vertical_fov_deg,
            })
        })
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    #[test]
    fn a_zoomed_camera_is_a_change_and_the_same_field_is_not() {
        let a = crate::Rig::builtin("aloha/transfer-cube").unwrap();
        assert_eq!(a.fov_change(&a), None);
        let mut b = a.clone();
        b.cameras[0].vertical_fov_deg = None;
        let c = a.fov_change(&b).unwrap();
        assert_eq!((c.from, c.to), (Some(45.0), None));
        assert_eq!(
            c.to_string(),
            "camera top has a vertical field of view of the simulator's own, not 45°"
        );
        // A camera only one rig has is not a change of field.
        b.cameras[0].name = "angle".into();
        assert_eq!(a.fov_change(&b), None);
    }
}
