//! Typed handles to the elements of a [`GltfBuilder`](super::GltfBuilder).
//!
//! Invariant: a handle is the index of its element in the builder that returned it, which
//! is also the element's index in the written glTF array; a handle is only meaningful for
//! that builder ([`GltfBuilder::validate`](super::GltfBuilder::validate) re-checks
//! every reference).

macro_rules! handle {
    ($(#[$doc:meta])* $name:ident) => {
        $(#[$doc])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
        pub struct $name(pub(crate) usize);

        impl $name {
            /// The element's index in its glTF array.
            pub fn index(self) -> usize {
                self.0
            }
        }
    };
}

handle!(
    /// A geometry added with [`add_geometry`](super::GltfBuilder::add_geometry), written once.
    GeometryId
);
handle!(
    /// A mesh added with [`add_mesh`](super::GltfBuilder::add_mesh).
    MeshId
);
handle!(
    /// An image added with [`add_image`](super::GltfBuilder::add_image).
    ImageId
);
handle!(
    /// A material added with [`add_material`](super::GltfBuilder::add_material).
    MaterialId
);
handle!(
    /// A node added with [`add_node`](super::GltfBuilder::add_node).
    NodeId
);
handle!(
    /// A camera added with [`add_camera`](super::GltfBuilder::add_camera).
    CameraId
);
handle!(
    /// A light added with [`add_point_light`](super::GltfBuilder::add_point_light).
    LightId
);
handle!(
    /// An animation added with [`add_animation`](super::GltfBuilder::add_animation).
    AnimationId
);
