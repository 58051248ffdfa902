//! Cages (schema/README.md, "Cage"; Corda et al. 2020): a deformed mesh's
//! `rel curvenet:cage` to a closed triangle `Mesh`, its rest-cage edits
//! (`points` time samples) and posed-cage edits
//! (`primvars:curvenet:posedCageOffsets`), read into [`CageData`].

use std::collections::HashMap;

use openusd::sdf::Value;
use openusd::usd;

use super::error::UsdError;
use super::read::{Stage, at};
use super::value;
use crate::data::{CageData, CageSample, MeshData};

type Result<T> = std::result::Result<T, UsdError>;

/// `rel curvenet:cage` on a deformed mesh: its cage.
pub const CAGE_REL: &str = "curvenet:cage";
/// `point3f[] primvars:curvenet:posedCageOffsets` on the cage: posed-cage edits ∂C′.
pub const POSED_CAGE_OFFSETS: &str = "primvars:curvenet:posedCageOffsets";

impl Stage {
    /// The cage of `mesh` (its `rel curvenet:cage`), or `None` when the mesh
    /// has no opinion on that relationship.
    ///
    /// Refused, naming the prim and the attribute (and the face, edge,
    /// vertex or time at fault): a relationship that targets nothing (an
    /// explicit empty list), several prims, a path with no prim, or a prim
    /// that is not a `Mesh`; a face that is not a triangle; time-sampled
    /// topology; indices out of range; a triangle that repeats a vertex; a
    /// cage that is not closed and consistently oriented (an edge used twice
    /// in one direction, or with no opposite); a cage that faces inwards
    /// (non-positive enclosed volume); a `points` or `posedCageOffsets`
    /// value (default or time sample) with another count than the cage's
    /// vertices, or a non-finite coordinate; `posedCageOffsets` with an
    /// interpolation other than `vertex`.
    pub fn cage(&self, mesh: &MeshData) -> Result<Option<CageData>> {
        let mesh_prim = self.prim(&mesh.path)?;
        let authored = mesh_prim
            .relationship(CAGE_REL)
            .has_authored_targets()
            .map_err(|e| UsdError::contract(&mesh.path, CAGE_REL, e.to_string()))?;
        if !authored {
            return Ok(None);
        }
        let targets = self.targets(&mesh_prim, CAGE_REL)?;
        let path = match targets.as_slice() {
            [] => {
                return Err(UsdError::contract(
                    &mesh.path,
                    CAGE_REL,
                    "targets nothing (an empty target list); remove the relationship for no cage",
                ));
            }
            [one] => one.clone(),
            many => {
                return Err(UsdError::contract(
                    &mesh.path,
                    CAGE_REL,
                    format!("targets {} prims ({}), a mesh has one cage", many.len(), many.join(", ")),
                ));
            }
        };
        if path == mesh.path {
            return Err(UsdError::contract(
                &mesh.path,
                CAGE_REL,
                "targets the mesh itself; a cage is a separate, coarse closed triangle Mesh around it",
            ));
        }
        if path.contains('.') {
            return Err(UsdError::contract(
                &mesh.path,
                CAGE_REL,
                format!("targets {path}, a property; a cage is a Mesh prim"),
            ));
        }
        if !self.has_prim(&path) {
            return Err(UsdError::contract(&mesh.path, CAGE_REL, format!("targets {path}, which is not on the stage")));
        }
        let prim = self.prim(&path)?;
        let ty = self.type_name(&prim)?;
        if ty != "Mesh" {
            return Err(UsdError::contract(
                &mesh.path,
                CAGE_REL,
                format!("targets {path}, a {ty:?}, but a cage is a triangle Mesh"),
            ));
        }

        // Topology: triangles only, static.
        let counts_v = self
            .static_value(&prim, "faceVertexCounts")?
            .ok_or_else(|| UsdError::contract(&path, "faceVertexCounts", "is missing"))?;
        let counts = value::ints(&counts_v).ok_or_else(|| {
            UsdError::contract(
                &path,
                "faceVertexCounts",
                format!("has type {}, expected int[]", value::kind(&counts_v)),
            )
        })?;
        if let Some(f) = counts.iter().position(|&c| c != 3) {
            return Err(UsdError::contract(
                &path,
                "faceVertexCounts",
                format!("face {f} has {} vertices, a cage is made of triangles", counts[f]),
            ));
        }
        let rest_v = self.required(&prim, "points", None)?;
        let rest_points = self.points_value(&prim, "points", &rest_v)?;
        let n = rest_points.len();
        finite_points(&rest_points, &path, "points", None)?;
        let indices_v = self
            .static_value(&prim, "faceVertexIndices")?
            .ok_or_else(|| UsdError::contract(&path, "faceVertexIndices", "is missing"))?;
        let indices = self.index_array(&prim, "faceVertexIndices", &indices_v, n)?;
        if indices.len() != 3 * counts.len() {
            return Err(UsdError::contract(
                &path,
                "faceVertexIndices",
                format!("has {} entries but faceVertexCounts sum to {}", indices.len(), 3 * counts.len()),
            ));
        }
        let left_handed = match self.value(&prim, "orientation", None)?.as_ref().and_then(value::token).as_deref() {
            None | Some("rightHanded") => false,
            Some("leftHanded") => true,
            Some(other) => {
                return Err(UsdError::contract(
                    &path,
                    "orientation",
                    format!("is {other:?}, expected rightHanded or leftHanded"),
                ));
            }
        };
        let triangles: Vec<[u32; 3]> = indices
            .chunks_exact(3)
            .map(|t| if left_handed { [t[0], t[2], t[1]] } else { [t[0], t[1], t[2]] })
            .collect();
        check_closed(&triangles, &path)?;
        let volume = signed_volume(&rest_points, &triangles);
        if volume.is_nan() || volume <= 0.0 {
            return Err(UsdError::contract(
                &path,
                "faceVertexIndices",
                format!(
                    "the triangles enclose a volume of {volume:e} with the points default: the cage faces \
                     inwards (a cage's triangles are counter-clockwise seen from outside)"
                ),
            ));
        }

        // Rest-cage edits and posed-cage edits.
        let rest_samples = self.cage_samples(&prim, &path, "points", n)?;
        let posed_offsets_default = match self.value(&prim, POSED_CAGE_OFFSETS, None)? {
            None => None,
            Some(v) => Some(self.cage_points(&prim, &path, POSED_CAGE_OFFSETS, &v, n, None)?),
        };
        if posed_offsets_default.is_some() || !self.sample_times(&prim, POSED_CAGE_OFFSETS)?.is_empty() {
            let interpolation = prim
                .attribute(POSED_CAGE_OFFSETS)
                .get_metadata::<Value>("interpolation")
                .map_err(|e| UsdError::contract(&path, POSED_CAGE_OFFSETS, e.to_string()))?;
            match interpolation.as_ref().and_then(value::token).as_deref() {
                None | Some("vertex") => {}
                Some(other) => {
                    return Err(UsdError::contract(
                        &path,
                        POSED_CAGE_OFFSETS,
                        format!("has interpolation {other:?}, expected \"vertex\" (one offset per cage vertex)"),
                    ));
                }
            }
        }
        let posed_offset_samples = self.cage_samples(&prim, &path, POSED_CAGE_OFFSETS, n)?;
        Ok(Some(CageData {
            mesh: mesh.path.clone(),
            path,
            rest_points,
            triangles,
            rest_samples,
            posed_offsets_default,
            posed_offset_samples,
        }))
    }

    fn cage_samples(&self, prim: &usd::Prim, path: &str, name: &str, n: usize) -> Result<Vec<CageSample>> {
        let mut out = Vec::new();
        for time in self.sample_times(prim, name)? {
            let v = self.required(prim, name, Some(time))?;
            let points = self.cage_points(prim, path, name, &v, n, Some(time))?;
            out.push(CageSample { time, points });
        }
        Ok(out)
    }

    fn cage_points(
        &self,
        prim: &usd::Prim,
        path: &str,
        name: &str,
        v: &Value,
        n: usize,
        time: Option<f64>,
    ) -> Result<Vec<[f64; 3]>> {
        let points = self.points_value(prim, name, v)?;
        if points.len() != n {
            return Err(UsdError::contract(
                path,
                name,
                format!("has {} entries{}, the cage has {n} vertices", points.len(), at(time)),
            ));
        }
        finite_points(&points, path, name, time)?;
        Ok(points)
    }
}

fn finite_points(points: &[[f64; 3]], path: &str, name: &str, time: Option<f64>) -> Result<()> {
    match points.iter().position(|p| !p.iter().all(|x| x.is_finite())) {
        None => Ok(()),
        Some(i) => Err(UsdError::contract(path, name, format!("entry {i} is {:?}{}, not finite", points[i], at(time)))),
    }
}

/// Every edge of the cage is used once in each direction: the cage is
/// closed and its triangles are consistently oriented.
fn check_closed(triangles: &[[u32; 3]], path: &str) -> Result<()> {
    let mut directed: HashMap<(u32, u32), usize> = HashMap::with_capacity(3 * triangles.len());
    for (f, t) in triangles.iter().enumerate() {
        if t[0] == t[1] || t[1] == t[2] || t[2] == t[0] {
            return Err(UsdError::contract(
                path,
                "faceVertexIndices",
                format!("triangle {f} is {t:?}, it repeats a vertex"),
            ));
        }
        for e in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            if let Some(g) = directed.insert(e, f) {
                return Err(UsdError::contract(
                    path,
                    "faceVertexIndices",
                    format!(
                        "edge {} -> {} is used in the same direction by triangles {g} and {f}: the cage is \
                         non-manifold there or its triangles are not consistently oriented",
                        e.0, e.1
                    ),
                ));
            }
        }
    }
    // Report the first open edge in triangle order, so the message is stable.
    for (f, t) in triangles.iter().enumerate() {
        for (u, v) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            if !directed.contains_key(&(v, u)) {
                return Err(UsdError::contract(
                    path,
                    "faceVertexIndices",
                    format!("edge {u} -> {v} of triangle {f} has no opposite edge: the cage is not closed"),
                ));
            }
        }
    }
    Ok(())
}

fn signed_volume(p: &[[f64; 3]], triangles: &[[u32; 3]]) -> f64 {
    triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| p[i as usize]);
            a[0] * (b[1] * c[2] - b[2] * c[1]) + a[1] * (b[2] * c[0] - b[0] * c[2]) + a[2] * (b[0] * c[1] - b[1] * c[0])
        })
        .sum::<f64>()
        / 6.0
}
