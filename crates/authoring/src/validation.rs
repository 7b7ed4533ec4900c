//! Checks of a [`GltfBuilder`] against the glTF rules the writer relies on: references in
//! range, one parent per node and no cycles, unit quaternions, finite numbers, factors in
//! range, strictly increasing key times, value counts that match the interpolation.

use super::animation::{AnimatedProperty, Channel, Interpolation};
use super::builder::GltfBuilder;
use super::error::AuthoringError;

impl GltfBuilder {
    /// Checks every reference and every glTF rule the writer relies on.
    ///
    /// # Errors
    /// [`AuthoringError::Invalid`] naming the first offending element.
    pub fn validate(&self) -> Result<(), AuthoringError> {
        self.validate_geometry()?;
        self.validate_images()?;
        self.validate_materials()?;
        self.validate_nodes()?;
        self.validate_cameras_and_lights()?;
        self.validate_animations()
    }

    fn validate_geometry(&self) -> Result<(), AuthoringError> {
        for (i, (name, geometry)) in self.geometries.iter().enumerate() {
            geometry
                .validate()
                .map_err(|m| invalid(format!("geometry {i} ({name:?}): {m}")))?;
        }
        for (i, mesh) in self.meshes.iter().enumerate() {
            if mesh.primitives.is_empty() {
                return Err(invalid(format!(
                    "mesh {i} ({:?}) has no primitives",
                    mesh.name
                )));
            }
            for p in &mesh.primitives {
                check_index("mesh", i, "geometry", p.geometry.0, self.geometries.len())?;
                if let Some(m) = p.material {
                    check_index("mesh", i, "material", m.0, self.materials.len())?;
                }
            }
            let targets =
                |p: &super::node::Primitive| self.geometries[p.geometry.0].1.morph_targets.len();
            let count = targets(&mesh.primitives[0]);
            if mesh.primitives.iter().any(|p| targets(p) != count) {
                return Err(invalid(format!(
                    "mesh {i} ({:?}): primitives have different numbers of morph targets",
                    mesh.name
                )));
            }
            let weights_ok = mesh.weights.is_empty()
                || (mesh.weights.len() == count && mesh.weights.iter().all(|w| w.is_finite()));
            if !weights_ok {
                return Err(invalid(format!(
                    "mesh {i} ({:?}) has {} morph weights for {count} morph targets",
                    mesh.name,
                    mesh.weights.len()
                )));
            }
        }
        Ok(())
    }

    fn validate_images(&self) -> Result<(), AuthoringError> {
        for (i, (name, image)) in self.images.iter().enumerate() {
            let name_ok = !name.is_empty()
                && name
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
            if !name_ok {
                return Err(invalid(format!(
                    "image {i} has a bad file name part {name:?}"
                )));
            }
            if self.images[..i].iter().any(|(other, _)| other == name) {
                return Err(invalid(format!("image name {name:?} is used twice")));
            }
            let expected = image.width as usize * image.height as usize * 4;
            if image.width == 0 || image.height == 0 || image.pixels.len() != expected {
                return Err(invalid(format!("image {i} ({name:?}) has a bad size")));
            }
        }
        Ok(())
    }

    fn validate_materials(&self) -> Result<(), AuthoringError> {
        for (i, m) in self.materials.iter().enumerate() {
            let unit = |x: f32| (0.0..=1.0).contains(&x);
            let ok = m.base_color.to_array().into_iter().all(unit)
                && unit(m.metallic)
                && unit(m.roughness)
                && m.transmission.is_none_or(unit)
                && m.ior.is_none_or(|ior| ior >= 1.0 && ior.is_finite());
            if !ok {
                return Err(invalid(format!(
                    "material {i} ({:?}) has a factor out of range",
                    m.name
                )));
            }
            if let Some(t) = m.base_color_texture {
                check_index("material", i, "image", t.image.0, self.images.len())?;
            }
        }
        Ok(())
    }

    fn validate_nodes(&self) -> Result<(), AuthoringError> {
        let n = self.nodes.len();
        let mut parent = vec![None; n];
        for (i, node) in self.nodes.iter().enumerate() {
            let finite =
                node.translation.is_finite() && node.scale.is_finite() && node.rotation.is_finite();
            if !finite || (node.rotation.length() - 1.0).abs() > 1e-4 {
                return Err(invalid(format!(
                    "node {i} ({:?}) has a bad transform",
                    node.name
                )));
            }
            if let Some(m) = node.mesh {
                check_index("node", i, "mesh", m.0, self.meshes.len())?;
            }
            if let Some(c) = node.camera {
                check_index("node", i, "camera", c.0, self.cameras.len())?;
            }
            if let Some(l) = node.light {
                check_index("node", i, "light", l.0, self.lights.len())?;
            }
            for c in &node.children {
                check_index("node", i, "child", c.0, n)?;
                if parent[c.0].replace(i).is_some() || c.0 == i {
                    return Err(invalid(format!("node {} has more than one parent", c.0)));
                }
            }
        }
        // With one parent each, a cycle is a walk up that never reaches a root.
        for start in 0..n {
            let mut at = start;
            for _ in 0..=n {
                match parent[at] {
                    Some(p) => at = p,
                    None => break,
                }
            }
            if parent[at].is_some() {
                return Err(invalid(format!("node {start} is in a cycle")));
            }
        }
        Ok(())
    }

    fn validate_cameras_and_lights(&self) -> Result<(), AuthoringError> {
        for (i, c) in self.cameras.iter().enumerate() {
            let ok = c.yfov > 0.0
                && c.yfov < std::f32::consts::PI
                && c.znear > 0.0
                && c.aspect_ratio.is_none_or(|a| a > 0.0 && a.is_finite())
                && c.zfar.is_none_or(|f| f > c.znear && f.is_finite());
            if !ok {
                return Err(invalid(format!(
                    "camera {i} ({:?}) has bad parameters",
                    c.name
                )));
            }
        }
        for (i, l) in self.lights.iter().enumerate() {
            let ok = l.color.is_finite()
                && l.color.min_element() >= 0.0
                && l.intensity >= 0.0
                && l.intensity.is_finite()
                && l.range.is_none_or(|r| r > 0.0 && r.is_finite());
            if !ok {
                return Err(invalid(format!(
                    "light {i} ({:?}) has bad parameters",
                    l.name
                )));
            }
        }
        Ok(())
    }

    fn validate_animations(&self) -> Result<(), AuthoringError> {
        for (a, animation) in self.animations.iter().enumerate() {
            let context = |c: usize| format!("animation {a} ({:?}) channel {c}", animation.name);
            if animation.channels.is_empty() {
                return Err(invalid(format!(
                    "animation {a} ({:?}) has no channels",
                    animation.name
                )));
            }
            for (c, ch) in animation.channels.iter().enumerate() {
                check_index("animation", a, "node", ch.node.0, self.nodes.len())?;
                let duplicate = animation.channels[..c]
                    .iter()
                    .any(|o| o.node == ch.node && o.property == ch.property);
                if duplicate {
                    return Err(invalid(format!(
                        "{}: node and property already animated",
                        context(c)
                    )));
                }
                let times_ok = !ch.times.is_empty()
                    && ch.times.iter().all(|t| t.is_finite() && *t >= 0.0)
                    && ch.times.windows(2).all(|w| w[0] < w[1]);
                if !times_ok {
                    return Err(invalid(format!(
                        "{}: times must be non-negative and strictly increasing",
                        context(c)
                    )));
                }
                if ch.values.len() != ch.times.len() * ch.values_per_key()
                    || ch.values.iter().any(|v| !v.is_finite())
                {
                    return Err(invalid(format!(
                        "{}: wrong number of key values",
                        context(c)
                    )));
                }
                if let AnimatedProperty::Weights { targets } = ch.property {
                    let mesh_targets = self.nodes[ch.node.0]
                        .mesh
                        .map_or(0, |m| self.morph_target_count(m));
                    if targets == 0 || targets != mesh_targets {
                        return Err(invalid(format!(
                            "{}: weights for {targets} morph targets, but the node's mesh has {mesh_targets}",
                            context(c)
                        )));
                    }
                }
                if ch.property == AnimatedProperty::Rotation {
                    check_unit_rotations(ch)
                        .map_err(|m| invalid(format!("{}: {m}", context(c))))?;
                }
            }
        }
        Ok(())
    }
}

fn check_unit_rotations(ch: &Channel) -> Result<(), String> {
    let stride = ch.values_per_key();
    let offset = if ch.interpolation == Interpolation::CubicSpline {
        4
    } else {
        0
    };
    for key in ch.values.chunks(stride) {
        let q = &key[offset..offset + 4];
        let length = q.iter().map(|x| x * x).sum::<f32>().sqrt();
        if (length - 1.0).abs() > 1e-4 {
            return Err("rotation key is not a unit quaternion".into());
        }
    }
    Ok(())
}

fn invalid(message: String) -> AuthoringError {
    AuthoringError::Invalid(message)
}

fn check_index(
    owner: &str,
    owner_index: usize,
    what: &str,
    index: usize,
    len: usize,
) -> Result<(), AuthoringError> {
    if index < len {
        Ok(())
    } else {
        Err(invalid(format!(
            "{owner} {owner_index} refers to {what} {index}, but there are {len}"
        )))
    }
}
