//! A small Wavefront OBJ loader, so "add mesh collider" takes `.obj` files as well as glTF
//! (Bevy loads glTF itself; it has no OBJ loader). Positions and faces only: polygons are
//! fanned into triangles, `v/vt/vn` references and negative (relative) indices are understood,
//! smooth per-vertex normals are computed. Materials, groups and texture
//! coordinates are ignored: a collider needs the surface only.

use bevy::asset::io::Reader;
use bevy::asset::{AssetLoader, LoadContext, RenderAssetUsages};
use bevy::mesh::{Indices, PrimitiveTopology};
use bevy::prelude::*;

/// Loads `.obj` files as [`Mesh`]es (registered by
/// [`ClothEditorPlugin`](super::ClothEditorPlugin)).
#[derive(Clone, Copy, Debug, Default, TypePath)]
pub struct ObjMeshLoader;

/// Why an OBJ file could not be read.
#[derive(Debug)]
pub enum ObjError {
    /// Reading the file failed.
    Io(std::io::Error),
    /// A line could not be understood (1-based line number and what is wrong).
    Parse {
        /// Line number, from 1.
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// The file has no faces.
    Empty,
}

impl core::fmt::Display for ObjError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            ObjError::Io(e) => write!(f, "cannot read the OBJ file: {e}"),
            ObjError::Parse { line, reason } => write!(f, "OBJ line {line}: {reason}"),
            ObjError::Empty => write!(f, "the OBJ file has no faces"),
        }
    }
}

impl std::error::Error for ObjError {}

impl AssetLoader for ObjMeshLoader {
    type Asset = Mesh;
    type Settings = ();
    type Error = ObjError;

    async fn load(
        &self,
        reader: &mut dyn Reader,
        _settings: &(),
        _load_context: &mut LoadContext<'_>,
    ) -> Result<Mesh, ObjError> {
        let mut bytes = Vec::new();
        reader.read_to_end(&mut bytes).await.map_err(ObjError::Io)?;
        parse_obj(&String::from_utf8_lossy(&bytes))
    }

    fn extensions(&self) -> &[&str] {
        &["obj"]
    }
}

/// Parses OBJ text into a triangle mesh with positions, smooth normals and `u32` indices.
///
/// # Errors
/// [`ObjError::Parse`] for a malformed vertex or face (naming the line), [`ObjError::Empty`]
/// when there is no face.
pub fn parse_obj(text: &str) -> Result<Mesh, ObjError> {
    let mut positions: Vec<Vec3> = Vec::new();
    let mut indices: Vec<u32> = Vec::new();
    for (k, raw) in text.lines().enumerate() {
        let line = k + 1;
        let bad = |reason: String| ObjError::Parse { line, reason };
        let mut words = raw.split('#').next().unwrap_or("").split_whitespace();
        match words.next() {
            Some("v") => {
                let xyz: Vec<f32> = words
                    .take(3)
                    .map(|w| w.parse::<f32>())
                    .collect::<Result<_, _>>()
                    .map_err(|e| bad(format!("vertex: {e}")))?;
                let [x, y, z] = xyz[..] else {
                    return Err(bad("a vertex needs x, y and z".into()));
                };
                let p = Vec3::new(x, y, z);
                if !p.is_finite() {
                    return Err(bad(format!("vertex {p} is not finite")));
                }
                positions.push(p);
            }
            Some("f") => {
                let n = positions.len() as i64;
                let corners: Vec<u32> = words
                    .map(|w| {
                        let first = w.split('/').next().unwrap_or("");
                        let i: i64 = first
                            .parse()
                            .map_err(|e| bad(format!("face index {w:?}: {e}")))?;
                        // 1-based, or negative: relative to the end of the list so far.
                        let i = if i < 0 { n + i } else { i - 1 };
                        if (0..n).contains(&i) {
                            Ok(i as u32)
                        } else {
                            Err(bad(format!("face index {w:?} is out of range (1..={n})")))
                        }
                    })
                    .collect::<Result<_, _>>()?;
                if corners.len() < 3 {
                    return Err(bad("a face needs at least 3 corners".into()));
                }
                for w in 1..corners.len() - 1 {
                    indices.extend([corners[0], corners[w], corners[w + 1]]);
                }
            }
            _ => {}
        }
    }
    if indices.is_empty() {
        return Err(ObjError::Empty);
    }
    let mut mesh = Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::default(),
    )
    .with_inserted_attribute(
        Mesh::ATTRIBUTE_POSITION,
        positions.iter().map(|p| p.to_array()).collect::<Vec<_>>(),
    )
    .with_inserted_indices(Indices::U32(indices));
    mesh.compute_smooth_normals();
    Ok(mesh)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quads_fan_into_triangles_and_bad_lines_are_named() {
        let text =
            "# a unit square\nv 0 0 0\nv 1 0 0\nv 1 0 1\nv 0 0 1\nvt 0 0\nf 1/1 2/1 3/1 -1\n";
        let mesh = parse_obj(text).unwrap();
        let Some(Indices::U32(ix)) = mesh.indices() else {
            panic!("no indices");
        };
        assert_eq!(ix, &[0, 1, 2, 0, 2, 3]);
        assert_eq!(mesh.count_vertices(), 4);
        match parse_obj("v 0 0 0\nv 1 0 0\nf 1 2 5\n") {
            Err(ObjError::Parse { line: 3, .. }) => {}
            other => panic!("{other:?}"),
        }
        assert!(matches!(
            parse_obj("v 0 0 nan\n"),
            Err(ObjError::Parse { line: 1, .. })
        ));
        assert!(matches!(parse_obj("v 0 0 0\n"), Err(ObjError::Empty)));
    }
}
