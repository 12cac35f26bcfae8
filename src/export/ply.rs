//! The layered point cloud as a PLY file for point-cloud tools (binary little-endian): per
//! point its position, colour, opacity, depth layer and whether it was synthesised.
//!
//! Axes and units: the photo's camera at frame 0 (OpenCV: x right, y down, z forward), scene
//! units (the depth stage's); both said in the header's comments. Written to a temporary file
//! and renamed ([`crate::image_io::write_atomic`]): a PLY is whole or absent.

use crate::error::{Error, Result};
use crate::image_io::{unit_to_u8, write_atomic};
use crate::stages::points::PointCloud;
use std::path::Path;

/// Bytes of one vertex record: 3 × f32 position, 4 × u8 colour and alpha, u16 layer, u8 flag.
pub const PLY_VERTEX_BYTES: usize = 12 + 4 + 2 + 1;

/// The PLY bytes of `cloud`.
pub fn ply_bytes(cloud: &PointCloud) -> Result<Vec<u8>> {
    let n = cloud.positions.len();
    if cloud.colours.len() != n
        || cloud.alphas.len() != n
        || cloud.layer.len() != n
        || cloud.inpainted.len() != n
    {
        return Err(Error::invalid(
            "internal: the point cloud's attributes differ in length",
        ));
    }
    let header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment makeit4d {} layered point cloud\ncomment axes: the photo's camera at frame 0, OpenCV (x right, y down, z forward); scene units\nelement vertex {n}\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nproperty uchar alpha\nproperty ushort layer\nproperty uchar inpainted\nend_header\n",
        env!("CARGO_PKG_VERSION")
    );
    let mut bytes = Vec::with_capacity(header.len() + n * PLY_VERTEX_BYTES);
    bytes.extend_from_slice(header.as_bytes());
    for i in 0..n {
        let p = cloud.positions[i];
        for v in [p.x, p.y, p.z] {
            // A non-finite position cannot be drawn: written at the origin, fully transparent.
            let v = if p.is_finite() { v } else { 0.0 };
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        let c = cloud.colours[i];
        bytes.extend_from_slice(&[unit_to_u8(c[0]), unit_to_u8(c[1]), unit_to_u8(c[2])]);
        let alpha = if p.is_finite() { cloud.alphas[i] } else { 0.0 };
        bytes.push(unit_to_u8(alpha));
        bytes.extend_from_slice(&cloud.layer[i].to_le_bytes());
        bytes.push(u8::from(cloud.inpainted[i]));
    }
    Ok(bytes)
}

/// Writes `cloud` to `path` as PLY, atomically.
pub fn write_ply(cloud: &PointCloud, path: &Path) -> Result<()> {
    write_atomic(path, &ply_bytes(cloud)?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn cloud() -> PointCloud {
        PointCloud {
            positions: vec![Vec3::new(1.0, -2.0, 3.5), Vec3::new(f32::NAN, 0.0, 1.0)],
            colours: vec![[1.0, 0.5, 0.0], [0.2, 0.2, 0.2]],
            alphas: vec![1.0, 1.0],
            tangent_u: vec![Vec3::X; 2],
            tangent_v: vec![Vec3::Y; 2],
            source_depth: vec![3.5, 1.0],
            source_pixel: vec![[0.0, 0.0]; 2],
            layer: vec![2, 0],
            inpainted: vec![true, false],
        }
    }

    #[test]
    fn the_records_read_back_as_written() {
        let bytes = ply_bytes(&cloud()).unwrap();
        let text = String::from_utf8_lossy(&bytes);
        let end = text.find("end_header\n").unwrap() + "end_header\n".len();
        assert!(text.starts_with("ply\nformat binary_little_endian 1.0\n"));
        assert!(text[..end].contains("element vertex 2\n"));
        assert_eq!(bytes.len(), end + 2 * PLY_VERTEX_BYTES);
        let r = &bytes[end..end + PLY_VERTEX_BYTES];
        let f = |k: usize| f32::from_le_bytes(r[4 * k..4 * k + 4].try_into().unwrap());
        assert_eq!((f(0), f(1), f(2)), (1.0, -2.0, 3.5));
        assert_eq!(&r[12..16], &[255, 128, 0, 255]);
        assert_eq!(u16::from_le_bytes([r[16], r[17]]), 2);
        assert_eq!(r[18], 1);
        // The non-finite point: at the origin, transparent.
        let r = &bytes[end + PLY_VERTEX_BYTES..];
        assert_eq!(&r[..12], &[0u8; 12]);
        assert_eq!(r[15], 0);
    }

    #[test]
    fn mismatched_attributes_and_unwritable_paths_are_refused() {
        let mut c = cloud();
        c.layer.pop();
        assert!(ply_bytes(&c).is_err());
        let dir = tempfile::tempdir().unwrap();
        let e = write_ply(&cloud(), &dir.path().join("missing/scene.ply")).unwrap_err();
        assert!(e.to_string().contains("scene.ply"), "{e}");
        // An empty cloud is a valid, empty PLY.
        let bytes = ply_bytes(&PointCloud::default()).unwrap();
        assert!(String::from_utf8_lossy(&bytes).contains("element vertex 0\n"));
    }
}
