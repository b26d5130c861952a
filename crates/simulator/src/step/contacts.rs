//! The contacts of a Newton iteration, less those between vertices sewn together.

use nalgebra::Vector3;

use super::{ColliderFrame, Simulator};
use crate::collide::{Collider, Contact, StepStart};
use crate::model::ClothModel;

/// The cap of [`Simulator::self_margin_m`]: half the 10th percentile of the rest edge lengths
/// (material space). Pairs of neighbouring triangles of flat cloth are about 0.4–0.9 edge
/// lengths apart; wider, most of them would become contact candidates.
pub(super) fn self_margin_cap(model: &ClothModel) -> f64 {
    let m = &model.mesh.material;
    let mut len: Vec<f64> = model
        .edges
        .iter()
        .map(|e| (m[e[0] as usize] - m[e[1] as usize]).norm())
        .filter(|l| l.is_finite() && *l > 0.0)
        .collect();
    if len.is_empty() {
        return 0.0;
    }
    let k = len.len() / 10;
    let (_, p10, _) = len.select_nth_unstable_by(k, f64::total_cmp);
    *p10 / 2.0
}
/// For each sewn vertex, the other vertices sewn to it (directly or through others: the
/// classes of the seam pairs), sorted. Contacts between them are dropped, as a mesh with its
/// seams welded would have no contact between a vertex and a triangle or edge it belongs to.
/// The two-hop neighbourhoods used before left cloth within two edges of a seam with no
/// repulsion: the circle skirt's panels crossed each other there for a few frames.
pub(super) fn seam_rings(model: &ClothModel) -> std::collections::HashMap<u32, Vec<u32>> {
    use std::collections::HashMap;
    let seams = &model.mesh.seam_pairs;
    let mut parent: HashMap<u32, u32> = HashMap::new();
    fn root(parent: &mut HashMap<u32, u32>, v: u32) -> u32 {
        let mut r = v;
        while let Some(&p) = parent.get(&r) {
            if p == r {
                break;
            }
            r = p;
        }
        parent.insert(v, r);
        r
    }
    for p in seams {
        for &v in p {
            parent.entry(v).or_insert(v);
        }
        let (a, b) = (root(&mut parent, p[0]), root(&mut parent, p[1]));
        if a != b {
            parent.insert(a.max(b), a.min(b));
        }
    }
    let vertices: Vec<u32> = parent.keys().copied().collect();
    let mut classes: HashMap<u32, Vec<u32>> = HashMap::new();
    for v in vertices {
        let r = root(&mut parent, v);
        classes.entry(r).or_default().push(v);
    }
    let mut rings = HashMap::new();
    for members in classes.values() {
        let mut sorted = members.clone();
        sorted.sort_unstable();
        for &v in members {
            rings.insert(v, sorted.iter().copied().filter(|&w| w != v).collect());
        }
    }
    rings
}

impl Simulator {
    /// Panels sewn together must be free to meet along the seam: no repulsion between a
    /// vertex and a triangle or edge holding a vertex sewn to it ([`seam_rings`]).
    pub(super) fn drop_seam_neighbours(&self, contacts: &mut Vec<Contact>) {
        if self.seam_ring.is_empty() {
            return;
        }
        contacts.retain(|c| match c {
            Contact::VertexObstacle { .. } | Contact::EdgeObstacle { .. } => true,
            Contact::VertexTriangle { v, t } => !self.sewn_together(&[*v], t),
            Contact::EdgeEdge { a, b } => !self.sewn_together(a, b),
        });
    }

    /// The contacts at `x` of cloth that began the step at `x_n` ([`StepStart`]).
    pub(super) fn contacts(
        &mut self,
        x: &[Vector3<f64>],
        since: StepStart<'_>,
        colliders: &[ColliderFrame<'_>],
    ) -> Vec<Contact> {
        let bodies: Vec<Collider<'_>> = colliders.iter().map(|c| (c.points, c.triangles)).collect();
        let mut params = self.params.collision;
        params.self_collision = self.cloth_contacts_on();
        self.detector.every_cloth_pair = self.params.collision.self_collision;
        let self_margin = self.self_margin_m();
        params.dhat_m += self_margin;
        self.detector.obstacle_extra_m = (self.obstacle_margin_m - self_margin).max(0.0);
        // Only fast mode without self-collision asks where bodies turn ([`slid_over_crease`]).
        self.detector.surface_turns = !self.params.newton_exact && !params.self_collision;
        let mut contacts = self.detector.find_contacts_since(
            x,
            since,
            &self.model.mesh.triangles,
            &self.model.edges,
            &bodies,
            &params,
        );
        self.drop_seam_neighbours(&mut contacts);
        if tracing::enabled!(tracing::Level::DEBUG) {
            let mut kinds = [0usize; 4];
            for c in &contacts {
                kinds[match c {
                    Contact::VertexObstacle { .. } => 0,
                    Contact::EdgeObstacle { .. } => 1,
                    Contact::VertexTriangle { .. } => 2,
                    Contact::EdgeEdge { .. } => 3,
                }] += 1;
            }
            tracing::debug!(
                vertex_obstacle = kinds[0],
                edge_obstacle = kinds[1],
                vertex_triangle = kinds[2],
                edge_edge = kinds[3],
                penetration_mm = self.detector.max_penetration() * 1e3,
                "contacts"
            );
        }
        contacts
    }
}
