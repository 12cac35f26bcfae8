//! Writing frame sequences, passes and video.
//!
//! Every file is written atomically (temporary name in the same folder, then renamed), so a
//! crashed, killed or cancelled export leaves only whole frames. `resume` skips frames that are
//! already complete (they decode and have the right size) and renders the rest; since rendering
//! is deterministic, a resumed export has the same bytes as an uninterrupted one.
//!
//! Layout of an export folder (`frame_%04d.png` is the default pattern):
//!
//! ```text
//! out/frame_0000.png …            colour, 8- or 16-bit RGB
//! out/depth/frame_0000.png …      depth pass: 16-bit grey, depth = value × scale (depth.json)
//! out/depth/depth.json            {"scale": …, "encoding": …}
//! out/coverage/frame_0000.png …   coverage (alpha) pass: 16-bit grey, coverage = value / 65535
//! out/layer0/frame_0000.png …     layers pass: layer k (0 = nearest) alone, RGBA (8- or 16-bit
//! out/layer1/…                    as the colour), alpha = its coverage; layer{k}/layer.json
//! out/motion/frame_0000.png …     motion pass: forward flow to the next frame, 16-bit RGB,
//!                                 flow = (RG − 32768) × scale px, B = known (motion.json)
//! out/camera/camera.json          camera pass: every path frame's intrinsics and pose
//! out/camera/camera.py            the same camera for Blender (`blender --python camera.py`)
//! out/video.mp4                   when a video was asked for and ffmpeg is present
//! ```
//!
//! A stereo export (`--stereo`) packs both eyes into each colour frame and writes each eye's
//! passes in the layout above under `out/left/` and `out/right/`. The layered scene for 3D
//! software is [`gltf`] (meshes and the path camera) and [`ply`] (the point cloud).
//!
//! The layers and motion passes are rendered by the CPU splatter whatever renderer made the
//! colour ([`passes`]). The camera pass covers the whole path, also with a frame range, and is
//! rewritten (same bytes) by every run.
//!
//! The folder: `options.rs` (what to write: the frame pattern, passes, video, the options and
//! the summary), `sequence.rs` ([`render_sequence`], resuming, the sidecars), `video.rs` (the
//! ffmpeg encoder); the passes' renders in [`passes`].

pub mod gltf;
mod options;
pub mod passes;
pub mod ply;
mod sequence;
pub mod stereo;
mod video;

pub use options::*;
pub use sequence::*;
