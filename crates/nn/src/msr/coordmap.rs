//! Coordinate maps (the paper's §3.2.1): each panel of a garment becomes an image on a uniform
//! grid in its material space, one pixel every `pixel_m` (2.5 mm: the fine mesh's edge), whose
//! three channels are the world position of the cloth at that material point. A mask marks the
//! pixels that carry information.
//!
//! **Boundary handling beyond the paper.** The paper masks exactly the pixels whose centre
//! falls inside a triangle, which leaves the outermost vertices of a panel with only some of
//! their four bilinear neighbours and shows as zigzags along edges and folds (its Fig. 22).
//! [`Boundary::Extended`] (the default) also keeps the ring of pixels just outside the panel and
//! fills them by linear extrapolation of the nearest triangle, so every vertex reads four valid
//! pixels and the read-out is as smooth at the boundary as inside
//! (`tests::extended_boundary_beats_inside_only_at_the_edges` measures the difference).
//!
//! The pixel ↔ triangle and vertex ↔ pixel relations depend only on the topology, so they are
//! computed once ([`Rasteriser`], [`Readout`]) and every frame is a weighted sum.

use std::path::Path;

use nalgebra::{Vector2, Vector3};
use ndarray::{Array2, Array3};
use serde::{Deserialize, Serialize};

use clothsr_geometry::error::{Error, Result};
use clothsr_geometry::mesh::ClothMesh;
use clothsr_geometry::mesh::TriLocator;

/// How pixels along panel boundaries are treated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Boundary {
    /// Only pixels inside a triangle (the paper).
    Inside,
    /// Inside pixels plus the one-pixel ring around them, filled by extrapolation.
    #[default]
    Extended,
}

/// The pixel grid of one panel: pixel (i, j) sits at material point origin + (j, i) · pixel_m
/// (row i along material v, column j along u).
#[derive(Debug, Clone, PartialEq)]
pub struct PanelGrid {
    /// Panel index in the mesh the grid was made from.
    pub panel: u32,
    /// Panel name (grids are matched to other meshes by it).
    pub name: String,
    /// Material position of pixel (0, 0), m.
    pub origin: Vector2<f64>,
    /// Pixel size, m.
    pub pixel_m: f64,
    /// Pixels that carry information, (height, width).
    pub mask: Array2<bool>,
    /// Pixels whose position lies inside the panel (a subset of `mask`).
    pub inside: Array2<bool>,
}

impl PanelGrid {
    /// Grids of every panel of `mesh` (the fine mesh defines them: both resolutions are
    /// rasterised on the same grids).
    pub fn for_mesh(mesh: &ClothMesh, pixel_m: f64, boundary: Boundary) -> Result<Vec<PanelGrid>> {
        if !(pixel_m.is_finite() && pixel_m > 0.0) {
            return Err(Error::Invalid(format!(
                "pixel size must be positive, got {pixel_m} m"
            )));
        }
        let mut out = Vec::with_capacity(mesh.panel_names.len());
        for (p, name) in mesh.panel_names.iter().enumerate() {
            let (mut lo, mut hi) = (
                Vector2::repeat(f64::INFINITY),
                Vector2::repeat(f64::NEG_INFINITY),
            );
            for (m, _) in mesh
                .material
                .iter()
                .zip(&mesh.panel_of_vertex)
                .filter(|(_, &q)| q == p as u32)
            {
                lo = lo.inf(m);
                hi = hi.sup(m);
            }
            if lo.x > hi.x {
                continue;
            }
            // One pixel of margin on every side for the extended ring.
            let origin = lo - Vector2::repeat(pixel_m);
            let w = ((hi.x - origin.x) / pixel_m).ceil() as usize + 2;
            let h = ((hi.y - origin.y) / pixel_m).ceil() as usize + 2;
            let locator = TriLocator::new(mesh, p as u32);
            let mut inside = Array2::from_elem((h, w), false);
            for ((i, j), cell) in inside.indexed_iter_mut() {
                let q = origin + Vector2::new(j as f64, i as f64) * pixel_m;
                if let Some((_, b)) = locator.locate(&q, false) {
                    *cell = b.iter().all(|&x| x >= -1e-9);
                }
            }
            let mask = match boundary {
                Boundary::Inside => inside.clone(),
                Boundary::Extended => dilate(&inside),
            };
            out.push(PanelGrid {
                panel: p as u32,
                name: name.clone(),
                origin,
                pixel_m,
                mask,
                inside,
            });
        }
        Ok(out)
    }

    /// (height, width).
    pub fn shape(&self) -> (usize, usize) {
        self.mask.dim()
    }

    /// Material position of pixel (i, j).
    pub fn position(&self, i: usize, j: usize) -> Vector2<f64> {
        self.origin + Vector2::new(j as f64, i as f64) * self.pixel_m
    }
}

/// Pixels set in `m` or next to one (8-neighbourhood).
fn dilate(m: &Array2<bool>) -> Array2<bool> {
    let (h, w) = m.dim();
    let mut out = m.clone();
    for ((i, j), &v) in m.indexed_iter() {
        if !v {
            continue;
        }
        for di in -1i64..=1 {
            for dj in -1i64..=1 {
                let (a, b) = (i as i64 + di, j as i64 + dj);
                if a >= 0 && b >= 0 && (a as usize) < h && (b as usize) < w {
                    out[(a as usize, b as usize)] = true;
                }
            }
        }
    }
    out
}

/// One panel's coordinate map: (3, H, W) positions (x, y, z) and its mask.
#[derive(Debug, Clone, PartialEq)]
pub struct CoordMap {
    /// Channels x, y, z; zero outside the mask.
    pub image: Array3<f32>,
    /// Pixels that carry information.
    pub mask: Array2<bool>,
}

/// (row, column, triangle vertices, barycentric weights) of a masked pixel.
type PixelSample = (u32, u32, [u32; 3], [f32; 3]);

/// Rasterises a mesh onto panel grids: per masked pixel, the mesh triangle (matched by panel
/// name) and the barycentric weights of the pixel's material point (extrapolated outside).
#[derive(Debug, Clone)]
pub struct Rasteriser {
    grids: Vec<PanelGrid>,
    /// The mesh's triangles (for vertex normals).
    triangles: Vec<[u32; 3]>,
    /// Phong tessellation blend (0: piecewise-linear, the paper).
    phong_alpha: f64,
    /// Per grid: every masked pixel's sample.
    samples: Vec<Vec<PixelSample>>,
}

impl Rasteriser {
    /// Prepares rasterising `mesh` (coarse or fine) onto `grids`.
    pub fn new(mesh: &ClothMesh, grids: &[PanelGrid]) -> Result<Rasteriser> {
        let mut samples = Vec::with_capacity(grids.len());
        for g in grids {
            let Some(p) = mesh.panel_names.iter().position(|n| *n == g.name) else {
                return Err(Error::Invalid(format!(
                    "panel '{}' of the grid is missing from the mesh",
                    g.name
                )));
            };
            let locator = TriLocator::new(mesh, p as u32);
            let mut s = Vec::new();
            for ((i, j), &m) in g.mask.indexed_iter() {
                if !m {
                    continue;
                }
                let q = g.position(i, j);
                let Some((t, b)) = locator.locate(&q, false) else {
                    return Err(Error::Invalid(format!(
                        "panel '{}' has no triangles to rasterise",
                        g.name
                    )));
                };
                s.push((
                    i as u32,
                    j as u32,
                    mesh.triangles[t as usize],
                    b.map(|x| x as f32),
                ));
            }
            samples.push(s);
        }
        Ok(Rasteriser {
            grids: grids.to_vec(),
            triangles: mesh.triangles.clone(),
            phong_alpha: 0.0,
            samples,
        })
    }

    /// Rasterises by Phong tessellation of the mesh with blend `alpha`
    /// ([`clothsr_geometry::transfer::phong_point`]; 0: piecewise-linear, as the paper) instead of linear
    /// interpolation: a coarse mesh's curvature then shows in its map, not only its chords.
    pub fn with_phong(mut self, alpha: f64) -> Rasteriser {
        self.phong_alpha = alpha;
        self
    }

    /// The grids.
    pub fn grids(&self) -> &[PanelGrid] {
        &self.grids
    }

    /// Coordinate maps of the mesh at positions `x` (one per grid).
    pub fn rasterise(&self, x: &[Vector3<f64>]) -> Vec<CoordMap> {
        // Vertex normals only for Phong tessellation (alpha 0 is linear interpolation).
        let n = if self.phong_alpha != 0.0 {
            clothsr_geometry::transfer::vertex_normals(&self.triangles, x)
        } else {
            Vec::new()
        };
        self.grids
            .iter()
            .zip(&self.samples)
            .map(|(g, s)| {
                let (h, w) = g.shape();
                let mut image = Array3::<f32>::zeros((3, h, w));
                for (i, j, t, b) in s {
                    let v = |k: usize| t[k] as usize;
                    let p = if n.is_empty() {
                        (x[v(0)].cast::<f32>() * b[0]
                            + x[v(1)].cast::<f32>() * b[1]
                            + x[v(2)].cast::<f32>() * b[2])
                            .cast::<f64>()
                    } else {
                        clothsr_geometry::transfer::phong_point(
                            [x[v(0)], x[v(1)], x[v(2)]],
                            [n[v(0)], n[v(1)], n[v(2)]],
                            b.map(f64::from),
                            self.phong_alpha,
                        )
                    };
                    for c in 0..3 {
                        image[(c, *i as usize, *j as usize)] = p[c] as f32;
                    }
                }
                CoordMap {
                    image,
                    mask: g.mask.clone(),
                }
            })
            .collect()
    }
}

/// Reads a mesh's vertices back from coordinate maps: each vertex interpolates the four pixels
/// around its material point bilinearly, over the masked ones only (weights renormalised);
/// the two vertices of each seam pair are averaged so seams stay closed.
#[derive(Debug, Clone)]
pub struct Readout {
    /// Per vertex: grid index, then up to four (flat pixel index, weight).
    taps: Vec<(u32, Vec<(u32, f32)>)>,
    seams: Vec<[u32; 2]>,
}

impl Readout {
    /// Prepares reading `mesh` from maps on `grids`.
    pub fn new(mesh: &ClothMesh, grids: &[PanelGrid]) -> Result<Readout> {
        let mut taps = Vec::with_capacity(mesh.num_vertices());
        for (v, m) in mesh.material.iter().enumerate() {
            let name = &mesh.panel_names[mesh.panel_of_vertex[v] as usize];
            let Some(gi) = grids.iter().position(|g| g.name == *name) else {
                return Err(Error::Invalid(format!(
                    "panel '{name}' has no coordinate map"
                )));
            };
            let g = &grids[gi];
            let (h, w) = g.shape();
            let f = (m - g.origin) / g.pixel_m;
            let (j0, i0) = (f.x.floor().max(0.0) as usize, f.y.floor().max(0.0) as usize);
            let (j0, i0) = (j0.min(w.saturating_sub(2)), i0.min(h.saturating_sub(2)));
            let (tx, ty) = (
                (f.x - j0 as f64).clamp(0.0, 1.0),
                (f.y - i0 as f64).clamp(0.0, 1.0),
            );
            let mut t: Vec<(u32, f32)> = Vec::with_capacity(4);
            for (di, dj, wgt) in [
                (0, 0, (1.0 - tx) * (1.0 - ty)),
                (0, 1, tx * (1.0 - ty)),
                (1, 0, (1.0 - tx) * ty),
                (1, 1, tx * ty),
            ] {
                let (i, j) = (i0 + di, j0 + dj);
                if i < h && j < w && g.mask[(i, j)] && wgt > 0.0 {
                    t.push(((i * w + j) as u32, wgt as f32));
                }
            }
            if t.is_empty() {
                // Inside-only masks can leave a boundary vertex with no masked neighbour: take
                // the nearest masked pixel.
                let near = g
                    .mask
                    .indexed_iter()
                    .filter(|(_, &k)| k)
                    .min_by(|a, b| {
                        let d = |(i, j): (usize, usize)| (g.position(i, j) - m).norm_squared();
                        d(a.0).total_cmp(&d(b.0))
                    })
                    .map(|((i, j), _)| i * w + j);
                let Some(k) = near else {
                    return Err(Error::Invalid(format!(
                        "panel '{name}' has an empty coordinate map"
                    )));
                };
                t.push((k as u32, 1.0));
            }
            let sum: f32 = t.iter().map(|x| x.1).sum();
            t.iter_mut().for_each(|x| x.1 /= sum);
            taps.push((gi as u32, t));
        }
        Ok(Readout {
            taps,
            seams: mesh.seam_pairs.clone(),
        })
    }

    /// Vertex positions from `maps` (one per grid, in the grids' order).
    pub fn read(&self, maps: &[CoordMap]) -> Vec<Vector3<f64>> {
        let mut x: Vec<Vector3<f64>> = self
            .taps
            .iter()
            .map(|(g, t)| {
                let img = &maps[*g as usize].image;
                let w = img.dim().2;
                let mut p = Vector3::<f64>::zeros();
                for (k, wgt) in t {
                    let (i, j) = (*k as usize / w, *k as usize % w);
                    for c in 0..3 {
                        p[c] += f64::from(img[(c, i, j)] * wgt);
                    }
                }
                p
            })
            .collect();
        for [a, b] in &self.seams {
            let m = (x[*a as usize] + x[*b as usize]) * 0.5;
            x[*a as usize] = m;
            x[*b as usize] = m;
        }
        x
    }
}

/// Per-channel normalisation of coordinate maps (§3.2.1: x, y and z scaled independently to
/// [0, 1] over the training data), saved next to the models.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Normalisation {
    /// Per channel minimum, m.
    pub min: [f32; 3],
    /// Per channel range (max − min), m; at least 1 mm.
    pub range: [f32; 3],
}

impl Normalisation {
    /// The bounds of `positions` (all frames of a data set).
    pub fn from_positions<'a>(
        positions: impl IntoIterator<Item = &'a Vector3<f64>>,
    ) -> Normalisation {
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for p in positions {
            for c in 0..3 {
                lo[c] = lo[c].min(p[c] as f32);
                hi[c] = hi[c].max(p[c] as f32);
            }
        }
        if lo[0] > hi[0] {
            lo = [0.0; 3];
            hi = [1.0; 3];
        }
        Normalisation {
            min: lo,
            range: std::array::from_fn(|c| (hi[c] - lo[c]).max(1e-3)),
        }
    }

    /// Metres to normalised units, in place, on masked pixels.
    pub fn normalise(&self, map: &mut CoordMap) {
        self.map_masked(map, |v, c| (v - self.min[c]) / self.range[c]);
    }

    /// Normalised units back to metres, in place, on masked pixels.
    pub fn denormalise(&self, map: &mut CoordMap) {
        self.map_masked(map, |v, c| v * self.range[c] + self.min[c]);
    }

    /// Applies `f(value, channel)` to masked pixels and zeroes the others.
    fn map_masked(&self, map: &mut CoordMap, f: impl Fn(f32, usize) -> f32) {
        for c in 0..3 {
            let mut ch = map.image.index_axis_mut(ndarray::Axis(0), c);
            ndarray::Zip::from(&mut ch)
                .and(&map.mask)
                .for_each(|v, &m| *v = if m { f(*v, c) } else { 0.0 });
        }
    }

    /// Writes JSON, atomically.
    pub fn save(&self, path: &Path) -> Result<()> {
        let text = serde_json::to_string_pretty(self)
            .map_err(|e| Error::Invalid(format!("normalisation: {e}")))?;
        clothsr_io::write_atomic(path, text.as_bytes())
    }

    /// Reads JSON.
    pub fn load(path: &Path) -> Result<Normalisation> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        serde_json::from_str(&text).map_err(|e| Error::bad_input(path, e.to_string()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clothsr_geometry::garment::Fabric;
    use clothsr_geometry::mesh::{mesh_garment, MeshOptions};
    use clothsr_geometry::scene::samples::flat_sheet;

    /// A wrinkled drape over material space: 1 mm wrinkles every 3 cm on a curved sheet.
    fn wrinkled(m: &Vector2<f64>) -> Vector3<f64> {
        Vector3::new(
            m.x,
            0.05 * (m.x * 5.0).sin() + 0.001 * (m.x * 209.0 + m.y * 40.0).sin(),
            m.y + 0.001 * (m.y * 150.0).cos(),
        )
    }

    /// A fine mesh of a quadrilateral panel with slanted edges, so that its boundary crosses
    /// the pixel grid at every phase.
    fn fine() -> ClothMesh {
        let mut g = flat_sheet("s", 0.2, 0.15, Vector3::zeros(), Fabric::default());
        g.panels[0].vertices = vec![
            Vector2::new(0.0, 0.0),
            Vector2::new(0.2, 0.031),
            Vector2::new(0.17, 0.15),
            Vector2::new(0.013, 0.121),
        ];
        mesh_garment(&g, &MeshOptions::with_edge(0.0025)).expect("mesh")
    }

    fn round_trip(mesh: &ClothMesh, boundary: Boundary) -> (f64, f64) {
        let grids = PanelGrid::for_mesh(mesh, 0.0025, boundary).expect("grids");
        let x: Vec<Vector3<f64>> = mesh.material.iter().map(wrinkled).collect();
        let maps = Rasteriser::new(mesh, &grids).expect("raster").rasterise(&x);
        for m in &maps {
            assert!(m.image.iter().all(|v| v.is_finite()));
        }
        let back = Readout::new(mesh, &grids).expect("readout").read(&maps);
        let boundary_v: std::collections::HashSet<u32> = {
            let mut count = std::collections::HashMap::new();
            for t in &mesh.triangles {
                for k in 0..3 {
                    let e = [t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3])];
                    *count.entry(e).or_insert(0) += 1;
                }
            }
            count
                .into_iter()
                .filter(|(_, c)| *c == 1)
                .flat_map(|(e, _)| e)
                .collect()
        };
        let (mut inner, mut edge) = (0.0f64, 0.0f64);
        for (v, (a, b)) in back.iter().zip(&x).enumerate() {
            let e = (a - b).norm();
            if boundary_v.contains(&(v as u32)) {
                edge = edge.max(e);
            } else {
                inner = inner.max(e);
            }
        }
        (inner, edge)
    }

    #[test]
    fn mesh_to_map_to_mesh_round_trips_within_a_tenth_of_a_millimetre() {
        let (inner, edge) = round_trip(&fine(), Boundary::Extended);
        assert!(inner < 1e-4, "interior error {:.4} mm", inner * 1e3);
        assert!(edge < 1e-4, "boundary error {:.4} mm", edge * 1e3);
    }

    #[test]
    fn extended_boundary_beats_inside_only_at_the_edges() {
        let mesh = fine();
        let (_, naive) = round_trip(&mesh, Boundary::Inside);
        let (_, extended) = round_trip(&mesh, Boundary::Extended);
        eprintln!(
            "boundary vertices, max error: inside-only {:.4} mm, extended {:.4} mm",
            naive * 1e3,
            extended * 1e3
        );
        assert!(
            extended * 3.0 < naive,
            "boundary error: extended {:.4} mm vs inside-only {:.4} mm",
            extended * 1e3,
            naive * 1e3
        );
    }

    #[test]
    fn seams_stay_closed_through_the_maps() {
        use clothsr_geometry::garment::{EdgeRef, Garment, Seam};
        let a = flat_sheet("t", 0.1, 0.08, Vector3::zeros(), Fabric::default());
        let mut front = a.panels[0].clone();
        front.name = "front".into();
        let mut back = front.clone();
        back.name = "back".into();
        let g = Garment {
            name: "tube".into(),
            panels: vec![front, back],
            seams: vec![Seam {
                a: EdgeRef { panel: 0, edge: 1 },
                b: EdgeRef { panel: 1, edge: 3 },
                reversed: true,
            }],
            fabric: Fabric::default(),
        };
        let mesh = mesh_garment(&g, &MeshOptions::with_edge(0.005)).expect("mesh");
        assert!(!mesh.seam_pairs.is_empty());
        let grids = PanelGrid::for_mesh(&mesh, 0.0025, Boundary::Extended).expect("grids");
        // Each panel gets its own world shape: the two sides of the seam disagree slightly.
        let x: Vec<Vector3<f64>> = mesh
            .material
            .iter()
            .zip(&mesh.panel_of_vertex)
            .map(|(m, &p)| wrinkled(m) + Vector3::new(0.0, 1e-3 * p as f64, 0.0))
            .collect();
        let maps = Rasteriser::new(&mesh, &grids)
            .expect("raster")
            .rasterise(&x);
        let back = Readout::new(&mesh, &grids).expect("readout").read(&maps);
        for [i, j] in &mesh.seam_pairs {
            assert!((back[*i as usize] - back[*j as usize]).norm() < 1e-12);
        }
    }

    #[test]
    fn normalisation_round_trips_and_saves() {
        let mesh = fine();
        let grids = PanelGrid::for_mesh(&mesh, 0.0025, Boundary::Extended).expect("grids");
        let x: Vec<Vector3<f64>> = mesh.material.iter().map(wrinkled).collect();
        let norm = Normalisation::from_positions(&x);
        let mut maps = Rasteriser::new(&mesh, &grids)
            .expect("raster")
            .rasterise(&x);
        let orig = maps[0].clone();
        norm.normalise(&mut maps[0]);
        let inside: Vec<f32> = maps[0]
            .image
            .indexed_iter()
            .filter(|((_, i, j), _)| grids[0].inside[(*i, *j)])
            .map(|(_, v)| *v)
            .collect();
        assert!(inside.iter().all(|v| (-1e-4..=1.0 + 1e-4).contains(v)));
        norm.denormalise(&mut maps[0]);
        let err = (&maps[0].image - &orig.image)
            .iter()
            .fold(0.0f32, |a, v| a.max(v.abs()));
        assert!(err < 1e-6, "{err}");
        let dir = tempfile::tempdir().expect("tmp");
        let p = dir.path().join("norm.json");
        norm.save(&p).expect("save");
        assert_eq!(Normalisation::load(&p).expect("load"), norm);
    }
}
