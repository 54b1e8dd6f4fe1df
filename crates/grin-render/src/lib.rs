//! The render description and the frame: what both backends read and write, so neither
//! compiles the other. grin-trace's CPU renderer and grin-gpu's marcher each take a
//! [`scene::RenderScene`] (camera, primitives, materials, lights, sky, the medium with its
//! [`settings::TraceSettings`]) and produce an [`image::Frame`] of the same layout,
//! written as EXR with AOV layers and a PNG preview.

pub mod camera;
pub mod image;
pub mod materials;
pub mod optics;
pub mod primitives;
pub mod rng;
pub mod scene;
pub mod sensor;
pub mod settings;
pub mod sky;
pub mod surface;
