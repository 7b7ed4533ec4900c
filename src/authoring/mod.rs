//! Authoring of the project's own animations (stub until the generator lands).
