//! The one error type of the authoring module: what went wrong while checking, encoding or
//! writing a scene built with [`GltfBuilder`](super::GltfBuilder).

use std::path::PathBuf;

/// Why a scene could not be encoded or written.
#[derive(Debug, thiserror::Error)]
pub enum AuthoringError {
    /// The builder's content breaks a glTF rule (the message names the element).
    #[error("invalid scene: {0}")]
    Invalid(String),
    /// A file or folder could not be created or written.
    #[error("{path}: {source}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// What the system said.
        source: std::io::Error,
    },
    /// An image could not be encoded as PNG.
    #[error("image {name:?}: cannot encode PNG: {source}")]
    Png {
        /// The image's name in the builder.
        name: String,
        /// What the encoder said.
        source: image::ImageError,
    },
    /// The glTF JSON could not be serialized.
    #[error("cannot serialize glTF JSON: {0}")]
    Json(#[from] serde_json::Error),
}
