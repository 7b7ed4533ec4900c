//! The camera file beside an exported frame (`camera_NNNN.json`): camera, lights and
//! background nodes, every value checked finite and the view directions non-zero.

use std::path::{Path, PathBuf};

use glam::{Mat4, Vec3};

use crate::scene::camera_file::CameraFile;
use crate::scene::{CameraDesc, LightDesc, NodeDesc, SceneDesc, Trs};

use super::{ObjError, error};

/// `camera_NNNN.json` beside `frame_NNNN.obj`, if it exists.
pub(super) fn sibling_camera(path: &Path) -> Option<PathBuf> {
    let stem = path.file_stem()?.to_str()?;
    let number = stem.strip_prefix("frame_")?;
    if number.is_empty() || !number.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    let candidate = path.with_file_name(format!("camera_{number}.json"));
    candidate.is_file().then_some(candidate)
}

pub(super) fn finite3(v: [f32; 3]) -> bool {
    v.iter().all(|c| c.is_finite())
}

/// World transform whose origin is `origin` and whose -Z is `forward` (unit), with `up` its
/// +Y when given (else any perpendicular).
pub(super) fn look_matrix(
    origin: Vec3,
    forward: Vec3,
    up: Option<Vec3>,
    right: Option<Vec3>,
) -> Mat4 {
    let z = -forward;
    let (x, y) = match (right, up) {
        (Some(x), Some(y)) => (x, y),
        _ => {
            let helper = if z.y.abs() < 0.9 { Vec3::Y } else { Vec3::X };
            let x = helper.cross(z).normalize_or(Vec3::X);
            (x, z.cross(x))
        }
    };
    Mat4::from_cols(
        x.extend(0.0),
        y.extend(0.0),
        z.extend(0.0),
        origin.extend(1.0),
    )
}

pub(super) fn matrix_node(name: String, matrix: Mat4) -> NodeDesc {
    let (scale, rotation, translation) = matrix.to_scale_rotation_translation();
    NodeDesc {
        name,
        local: Trs {
            translation,
            rotation,
            scale,
        },
        matrix: Some(matrix),
        ..Default::default()
    }
}

/// An error naming `what` when a colour or light value has a negative component: light of
/// negative power has no meaning, and shading would subtract it.
fn refuse_negative(path: &Path, what: &str, value: [f32; 3]) -> Result<(), ObjError> {
    if value.iter().any(|&c| c < 0.0) {
        return Err(error(
            path,
            None,
            format!("{what} {value:?} has a negative component (colours and light are 0 or more)"),
        ));
    }
    Ok(())
}

/// Adds the camera, lights and background of an export's camera file.
pub(super) fn add_camera_file(scene: &mut SceneDesc, path: &Path) -> Result<(), ObjError> {
    let text = crate::scene::sources::read_to_string(path)
        .map_err(|e| error(path, None, format!("cannot read file: {e}")))?;
    let file: CameraFile = serde_json::from_str(&text)
        .map_err(|e| error(path, Some(e.line()), format!("bad camera file: {e}")))?;
    let vectors = [file.eye, file.forward, file.up, file.right, file.background];
    // The renderer uses this value as given (no substitute), so refuse what it cannot use.
    let yfov = file.yfov_radians;
    if !(yfov > 0.0 && yfov < std::f32::consts::PI) {
        return Err(error(
            path,
            None,
            format!("camera has yfov_radians {yfov}, outside (0, pi)"),
        ));
    }
    if !vectors.iter().all(|v| finite3(*v)) {
        return Err(error(path, None, "camera has a non-finite vector"));
    }
    refuse_negative(path, "background", file.background)?;
    if let Some(problem) = degenerate_view(&file) {
        return Err(error(path, None, format!("camera: {problem}")));
    }
    // The exact fields (bit patterns) when they are present and agree with the decimals'
    // magnitude; the decimals otherwise.
    let exact = |v: [f32; 3], bits: [u32; 3]| {
        let b = bits.map(f32::from_bits);
        if (Vec3::from(b) - Vec3::from(v)).length() <= 1e-5 {
            Vec3::from(b)
        } else {
            Vec3::from(v)
        }
    };
    let eye = exact(file.eye, file.bits.eye);
    let forward = exact(file.forward, file.bits.forward);
    let up = exact(file.up, file.bits.up);
    let right = exact(file.right, file.bits.right);
    let camera_node = scene.nodes.len();
    scene.cameras.push(CameraDesc {
        yfov: file.yfov_radians,
        znear: 0.01,
    });
    let mut node = matrix_node(
        "camera".into(),
        look_matrix(eye, forward, Some(up), Some(right)),
    );
    node.camera = Some(scene.cameras.len() - 1);
    scene.nodes.push(node);
    scene.roots.push(camera_node);
    for (i, light) in file.lights.iter().enumerate() {
        let kind = light.light_kind().ok_or_else(|| {
            error(
                path,
                None,
                format!("light {i}: unknown kind {:?}", light.kind),
            )
        })?;
        let finite = finite3(light.position)
            && finite3(light.direction)
            && finite3(light.intensity)
            && light.range.is_none_or(f32::is_finite);
        if !finite {
            return Err(error(path, None, format!("light {i}: non-finite value")));
        }
        refuse_negative(path, &format!("light {i}: intensity"), light.intensity)?;
        scene.lights.push(LightDesc {
            kind,
            color: Vec3::from(light.intensity),
            intensity: 1.0,
            range: light.range,
            inverse_square: light.inverse_square,
        });
        let direction = Vec3::from(light.direction).normalize_or(Vec3::NEG_Y);
        let mut node = matrix_node(
            format!("light {i}"),
            look_matrix(Vec3::from(light.position), direction, None, None),
        );
        node.light = Some(scene.lights.len() - 1);
        scene.roots.push(scene.nodes.len());
        scene.nodes.push(node);
    }
    scene.background = Vec3::from(file.background);
    Ok(())
}

/// Why a camera file's view directions cannot place a camera: a zero (or sub-1e-6)
/// `forward`, `up` or `right`, or `up` parallel to `forward`.
fn degenerate_view(file: &CameraFile) -> Option<String> {
    const MIN_LENGTH: f32 = 1e-6;
    for (name, v) in [
        ("forward", file.forward),
        ("up", file.up),
        ("right", file.right),
    ] {
        if Vec3::from(v).length() < MIN_LENGTH {
            return Some(format!("{name} {v:?} has zero length"));
        }
    }
    let (forward, up) = (Vec3::from(file.forward), Vec3::from(file.up));
    if forward.normalize().cross(up.normalize()).length() < MIN_LENGTH {
        return Some(format!(
            "up {:?} is parallel to forward {:?}",
            file.up, file.forward
        ));
    }
    None
}
