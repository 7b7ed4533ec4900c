//! The frame clock: which time each frame number shows. A frame's image depends only on
//! this time, never on the frames rendered before it.

use crate::scene::SceneDesc;

/// Which time each frame number shows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FrameClock {
    /// Frame `i` at `i / fps` seconds.
    Fps(f64),
    /// The scene's own frame times (AFF `a start end frames`).
    Scene(crate::scene::FrameTimes),
}

impl FrameClock {
    /// The clock for a scene: `--fps` when given, else the scene's own frame times, else
    /// 30 frames per second.
    pub fn for_scene(scene: &SceneDesc, fps: Option<f64>) -> FrameClock {
        match (fps, scene.frame_times) {
            (Some(fps), _) => FrameClock::Fps(fps),
            (None, Some(times)) => FrameClock::Scene(times),
            (None, None) => FrameClock::Fps(30.0),
        }
    }

    /// Time of frame `frame` in seconds.
    pub fn time(&self, frame: u32) -> f32 {
        match self {
            FrameClock::Fps(fps) => (frame as f64 / fps) as f32,
            FrameClock::Scene(times) => times.time(frame),
        }
    }

    /// The frames that cover an animation of `duration_s` once (`0..round(duration * fps)`,
    /// at least one), or all of the scene's own frames.
    pub fn default_frames(&self, duration_s: f32) -> std::ops::Range<u32> {
        match self {
            FrameClock::Fps(fps) => 0..((duration_s as f64 * fps).round().clamp(1.0, 1e6) as u32),
            FrameClock::Scene(times) => 0..times.frames.max(1),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fps_clock_maps_frames_to_seconds_and_covers_the_duration_once() {
        let clock = FrameClock::Fps(24.0);
        assert_eq!(clock.time(0), 0.0);
        assert_eq!(clock.time(48), 2.0);
        assert_eq!(clock.default_frames(2.0), 0..48);
        // A static scene still renders one frame.
        assert_eq!(clock.default_frames(0.0), 0..1);
    }

    #[test]
    fn default_frames_cover_the_animation_once() {
        assert_eq!(FrameClock::Fps(30.0).default_frames(1.6), 0..48);
        assert_eq!(FrameClock::Fps(30.0).default_frames(0.0), 0..1);
        let aff = FrameClock::Scene(crate::scene::FrameTimes {
            start: 0.0,
            end: 20.0,
            frames: 800,
        });
        assert_eq!(aff.default_frames(123.0), 0..800);
        assert_eq!(aff.time(799), 20.0);
        assert_eq!(aff.time(0), 0.0);
    }
}
