//! A record of every ray a frame traces, for `mipray export --rays` (the ray file) and
//! `mipray bench --rays FILE`: any tracer can then trace exactly the rays a real frame
//! traced, class by class, and check its answers against the ones recorded here.
//!
//! Recording is off unless a render asks for it ([`RayLog`] in `TraceCounters`); when off it
//! costs one predictable branch per ray. Rays are recorded in the order the tile traced them
//! and tiles are joined in film order, so the log is the same for any thread count.

use glam::Vec3A;

use crate::accel::{Hit, TriangleRef};

/// The class of a traced ray (the `class` field of the ray file).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u32)]
pub enum RayClass {
    /// From the camera through a pixel sample.
    Primary = 0,
    /// From a hit toward a light: does anything lie in between?
    Shadow = 1,
    /// A mirror reflection (also total internal reflection).
    Reflection = 2,
    /// A refraction through glass.
    Refraction = 3,
}

impl RayClass {
    pub const ALL: [RayClass; 4] = [
        RayClass::Primary,
        RayClass::Shadow,
        RayClass::Reflection,
        RayClass::Refraction,
    ];

    /// The class of file value `v`.
    pub fn from_u32(v: u32) -> Option<RayClass> {
        RayClass::ALL.get(v as usize).copied()
    }

    pub fn name(self) -> &'static str {
        match self {
            RayClass::Primary => "primary",
            RayClass::Shadow => "shadow",
            RayClass::Reflection => "reflection",
            RayClass::Refraction => "refraction",
        }
    }
}

/// What a ray found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RayAnswer {
    /// A closest-hit query (primary, reflection, refraction): the triangle and distance.
    Closest(Option<(TriangleRef, f32)>),
    /// An occlusion query (shadow): whether any surface lies within the ray's interval. The
    /// integrator itself continues through glass and multiplies its transmission; the record
    /// keeps the geometric answer, which is what any tracer's occlusion query computes.
    Blocked(bool),
}

/// One ray as the frame traced it: `direction` as traced (not renormalised), searched over
/// `[t_min, t_max)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TracedRay {
    pub origin: Vec3A,
    pub direction: Vec3A,
    pub t_min: f32,
    pub t_max: f32,
    pub class: RayClass,
    /// `y * width + x` of the pixel whose sample spawned the ray.
    pub pixel: u32,
    pub answer: RayAnswer,
}

/// The rays of one tile (then one frame).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RayLog {
    pub rays: Vec<TracedRay>,
}

impl RayLog {
    /// Records a closest-hit ray of a sample of `pixel`.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn closest(
        &mut self,
        pixel: u32,
        class: RayClass,
        origin: Vec3A,
        direction: Vec3A,
        t_max: f32,
        hit: Option<Hit>,
    ) {
        self.rays.push(TracedRay {
            origin,
            direction,
            t_min: 0.0,
            t_max,
            class,
            pixel,
            answer: RayAnswer::Closest(hit.map(|h| (h.triangle_ref(), h.t))),
        });
    }

    /// Records a shadow ray of a sample of `pixel`.
    pub(super) fn shadow(
        &mut self,
        pixel: u32,
        origin: Vec3A,
        direction: Vec3A,
        t_max: f32,
        blocked: bool,
    ) {
        self.rays.push(TracedRay {
            origin,
            direction,
            t_min: 0.0,
            t_max,
            class: RayClass::Shadow,
            pixel,
            answer: RayAnswer::Blocked(blocked),
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn classes_round_trip_through_their_file_values() {
        for class in RayClass::ALL {
            assert_eq!(RayClass::from_u32(class as u32), Some(class));
        }
        assert_eq!(RayClass::from_u32(4), None);
        assert_eq!(RayClass::Refraction as u32, 3);
    }
}
