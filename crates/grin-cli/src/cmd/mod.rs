//! One module per subcommand.

pub mod bake;
pub mod bench;
pub mod dataset;
pub mod export;
pub mod info;
pub mod info_vdb;
pub mod render;
pub mod trace;
pub mod view;
