//! The method, one module per stage. Each stage is a pure function of its inputs and
//! parameters (`../docs/algorithms.md`).

pub mod depth;
pub mod inpaint;
pub mod layers;
pub mod motion;
pub mod outpaint;
pub mod points;
