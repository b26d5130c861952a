//! Reader for GarmentCode sewing-pattern specifications (`*_specification.json`) and the older
//! Garment-Pattern-Generator templates.
//!
//! Format: `pattern.panels` maps panel names to `{translation, rotation, vertices, edges}`; each
//! edge has `endpoints` and an optional `curvature`, either `{type: circle|quadratic|cubic,
//! params}` (GarmentCode) or a bare `[x, y]` quadratic control point (older templates). With
//! `properties.curvature_coords = "relative"` a control point `(s, t)` lies at
//! `start + s·(end − start) + t·perp(end − start)` with `perp(x, y) = (−y, x)`. Circle params are
//! `[radius, large_arc, right]` in pattern units. `properties.units_in_meter` converts lengths
//! (100 for cm). `pattern.stitches` lists pairs of `{panel, edge}`.

use std::path::Path;

use nalgebra::{Vector2, Vector3};
use serde_json::Value;

use super::{Curve, EdgeRef, Fabric, Garment, Panel, PanelEdge, Placement, Seam};
use crate::error::{Error, Result};

/// Reads a GarmentCode JSON file into a validated [`Garment`] made of `fabric`.
pub fn read(path: &Path, fabric: Fabric) -> Result<Garment> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let name = path
        .file_stem()
        .and_then(|s| s.to_str())
        .map(|s| s.trim_end_matches("_specification").to_string())
        .unwrap_or_else(|| "garment".into());
    parse(&text, &name, fabric).map_err(|e| e.in_file(path))
}

/// Parses GarmentCode JSON text. Errors are [`Error::Invalid`] naming the element.
pub fn parse(text: &str, name: &str, fabric: Fabric) -> Result<Garment> {
    let root: Value =
        serde_json::from_str(text).map_err(|e| Error::Invalid(format!("malformed JSON: {e}")))?;
    let invalid = |m: String| Error::Invalid(m);
    let pattern = root
        .get("pattern")
        .ok_or_else(|| invalid("no 'pattern' object: not a GarmentCode specification".into()))?;
    let props = root.get("properties").cloned().unwrap_or(Value::Null);
    let units = props.get("units_in_meter").ok_or_else(|| {
        invalid("properties.units_in_meter is missing: cannot tell the pattern's units".into())
    })?;
    let units_in_meter = units
        .as_f64()
        .filter(|u| u.is_finite() && *u > 0.0)
        .ok_or_else(|| {
            invalid(format!(
                "properties.units_in_meter = {units}: unknown units"
            ))
        })?;
    let scale = 1.0 / units_in_meter;
    let relative = match props.get("curvature_coords").and_then(Value::as_str) {
        None | Some("relative") => true,
        Some("absolute") => false,
        Some(other) => {
            return Err(invalid(format!(
                "properties.curvature_coords = '{other}' is not supported"
            )))
        }
    };

    let panels_obj = pattern
        .get("panels")
        .and_then(Value::as_object)
        .ok_or_else(|| invalid("pattern.panels is missing or not an object".into()))?;
    // Panel order: `panel_order` when present and complete, else the file's order.
    let mut order: Vec<String> = pattern
        .get("panel_order")
        .and_then(Value::as_array)
        .map(|a| {
            a.iter()
                .filter_map(|v| v.as_str().map(String::from))
                .collect()
        })
        .unwrap_or_default();
    if order.len() != panels_obj.len() || !order.iter().all(|n| panels_obj.contains_key(n)) {
        order = panels_obj.keys().cloned().collect();
    }
    let mut panels = Vec::with_capacity(order.len());
    for pname in &order {
        panels.push(parse_panel(pname, &panels_obj[pname], scale, relative)?);
    }

    let mut seams = Vec::new();
    if let Some(stitches) = pattern.get("stitches") {
        let stitches = stitches
            .as_array()
            .ok_or_else(|| invalid("pattern.stitches is not an array".into()))?;
        for (s, st) in stitches.iter().enumerate() {
            let sides = st.as_array().filter(|a| a.len() >= 2).ok_or_else(|| {
                invalid(format!("stitch {s}: expected a pair of {{panel, edge}}"))
            })?;
            let mut refs = [EdgeRef { panel: 0, edge: 0 }; 2];
            for (k, side) in sides.iter().take(2).enumerate() {
                let pn = side
                    .get("panel")
                    .and_then(Value::as_str)
                    .ok_or_else(|| invalid(format!("stitch {s} side {k}: no 'panel' name")))?;
                let panel = order
                    .iter()
                    .position(|n| n == pn)
                    .ok_or_else(|| invalid(format!("stitch {s}: unknown panel '{pn}'")))?;
                let edge = side
                    .get("edge")
                    .and_then(Value::as_u64)
                    .ok_or_else(|| invalid(format!("stitch {s} side {k}: no 'edge' index")))?
                    as usize;
                refs[k] = EdgeRef { panel, edge };
            }
            seams.push(Seam {
                a: refs[0],
                b: refs[1],
                reversed: true,
            });
        }
    }

    let mut garment = Garment {
        name: name.to_string(),
        panels,
        seams,
        fabric,
    };
    garment.validate()?;
    garment.orient_seams_by_placement();
    Ok(garment)
}

fn number_list(v: &Value, what: &str, n: usize) -> Result<Vec<f64>> {
    let arr = v
        .as_array()
        .filter(|a| a.len() == n)
        .ok_or_else(|| Error::Invalid(format!("{what}: expected {n} numbers, got {v}")))?;
    arr.iter()
        .map(|x| {
            x.as_f64()
                .filter(|f| f.is_finite())
                .ok_or_else(|| Error::Invalid(format!("{what}: '{x}' is not a finite number")))
        })
        .collect()
}

fn parse_panel(name: &str, v: &Value, scale: f64, relative: bool) -> Result<Panel> {
    let invalid = |m: String| Error::Invalid(m);
    let verts = v
        .get("vertices")
        .and_then(Value::as_array)
        .ok_or_else(|| invalid(format!("panel '{name}': no 'vertices' array")))?;
    let vertices = verts
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let xy = number_list(p, &format!("panel '{name}' vertex {i}"), 2)?;
            Ok(Vector2::new(xy[0], xy[1]) * scale)
        })
        .collect::<Result<Vec<_>>>()?;
    let edges_v = v
        .get("edges")
        .and_then(Value::as_array)
        .ok_or_else(|| invalid(format!("panel '{name}': no 'edges' array")))?;
    let mut edges = Vec::with_capacity(edges_v.len());
    for (i, e) in edges_v.iter().enumerate() {
        let what = format!("panel '{name}' edge {i}");
        let ends = e
            .get("endpoints")
            .and_then(Value::as_array)
            .filter(|a| a.len() == 2)
            .ok_or_else(|| invalid(format!("{what}: 'endpoints' must be a pair of indices")))?;
        let idx = |k: usize| {
            ends[k]
                .as_u64()
                .map(|x| x as usize)
                .filter(|x| *x < vertices.len())
                .ok_or_else(|| {
                    invalid(format!(
                        "{what}: endpoint {} is not a vertex index (panel has {} vertices)",
                        ends[k],
                        vertices.len()
                    ))
                })
        };
        let (start, end) = (idx(0)?, idx(1)?);
        let (a, b) = (vertices[start], vertices[end]);
        let to_abs = |p: &[f64]| {
            let q = Vector2::new(p[0], p[1]);
            if relative {
                let d = b - a;
                a + d * q.x + Vector2::new(-d.y, d.x) * q.y
            } else {
                q * scale
            }
        };
        let curve = match e.get("curvature") {
            None | Some(Value::Null) => Curve::Straight,
            Some(c @ Value::Array(_)) => Curve::Quadratic {
                control: to_abs(&number_list(c, &format!("{what} curvature"), 2)?),
            },
            Some(c) => {
                let ty = c
                    .get("type")
                    .and_then(Value::as_str)
                    .ok_or_else(|| invalid(format!("{what}: curvature has no 'type'")))?;
                let params = c
                    .get("params")
                    .ok_or_else(|| invalid(format!("{what}: curvature has no 'params'")))?;
                let point = |k: usize| -> Result<Vector2<f64>> {
                    let p = params.get(k).ok_or_else(|| {
                        invalid(format!("{what}: {ty} curvature needs {} points", k + 1))
                    })?;
                    Ok(to_abs(&number_list(
                        p,
                        &format!("{what} curvature point {k}"),
                        2,
                    )?))
                };
                match ty {
                    "quadratic" => Curve::Quadratic { control: point(0)? },
                    "cubic" => Curve::Cubic {
                        control1: point(0)?,
                        control2: point(1)?,
                    },
                    "circle" => {
                        let p = number_list(params, &format!("{what} circle params"), 3)?;
                        if p[0] <= 0.0 {
                            return Err(invalid(format!(
                                "{what}: circle radius {} is not positive",
                                p[0]
                            )));
                        }
                        Curve::Arc {
                            radius_m: p[0] * scale,
                            large_arc: p[1] != 0.0,
                            right: p[2] != 0.0,
                        }
                    }
                    other => {
                        return Err(invalid(format!("{what}: unknown curvature type '{other}'")))
                    }
                }
            }
        };
        // Curvature in range: control points within ten edge lengths of the edge, and a circle
        // no smaller than the edge allows (SVG rounds a radius just short of half the chord
        // up; a much smaller one is an error in the pattern, not rounding).
        let chord = (b - a).norm();
        let far = |c: &Vector2<f64>| (c - (a + b) * 0.5).norm() > 10.0 * chord;
        match &curve {
            Curve::Quadratic { control: c } | Curve::Cubic { control1: c, .. } if far(c) => {
                return Err(invalid(format!(
                    "{what}: a curvature control point lies {:.3} m from a {chord:.3} m edge \
                     (more than ten edge lengths): curvature out of range",
                    (c - (a + b) * 0.5).norm()
                )))
            }
            Curve::Cubic { control2: c, .. } if far(c) => {
                return Err(invalid(format!(
                    "{what}: a curvature control point lies {:.3} m from a {chord:.3} m edge \
                     (more than ten edge lengths): curvature out of range",
                    (c - (a + b) * 0.5).norm()
                )))
            }
            Curve::Arc { radius_m, .. } if *radius_m < 0.45 * chord => {
                return Err(invalid(format!(
                    "{what}: circle radius {radius_m:.4} m is far shorter than half its chord \
                     ({:.4} m)",
                    0.5 * chord
                )))
            }
            _ => {}
        }
        edges.push(PanelEdge { start, end, curve });
    }
    let translation = match v.get("translation") {
        Some(t) => number_list(t, &format!("panel '{name}' translation"), 3)?,
        None => vec![0.0; 3],
    };
    let rotation = match v.get("rotation") {
        Some(r) => number_list(r, &format!("panel '{name}' rotation"), 3)?,
        None => vec![0.0; 3],
    };
    Ok(Panel {
        name: name.to_string(),
        vertices,
        edges,
        placement: Placement {
            translation_m: Vector3::new(translation[0], translation[1], translation[2]) * scale,
            rotation_xyz_deg: Vector3::new(rotation[0], rotation[1], rotation[2]),
        },
    })
}
