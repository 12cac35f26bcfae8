//! makeit4d: one still photo to a long, consistent, living fly-through video (Make-It-4D,
//! ACM MM 2023). This library holds the whole method with no GUI in it; the command line and
//! the editor are thin front ends over it.

pub mod app;
pub mod error;
pub mod eval;
pub mod export;
pub mod geometry;
pub mod image_io;
pub mod metrics;
pub mod ml;
pub mod models;
pub mod path;
pub mod progress;
pub mod project;
pub mod raster;
pub mod render;
pub mod scene;
pub mod stages;
pub mod workflow;

pub use error::{Error, Result};
