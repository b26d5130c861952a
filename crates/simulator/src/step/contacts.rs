//! The contacts of a Newton iteration, less those between vertices sewn together.

use nalgebra::Vector3;
use rayon::prelude::*;

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

/// Body contacts held through one step's Newton iterations for cloth caught where a body
/// overlaps itself. An avatar's thighs pressed together in a walk pass through each other:
/// cloth between them is inside the body whichever way it goes out. Pushed out of one thigh
/// through its nearest surface, it lands inside the other, where either the other's nearest
/// surface pushes it back (its contacts reverse) or, nearer the first thigh's surface from
/// outside, it is found outside with no contact at all and its neighbours pull it back in
/// (its contacts vanish while it is still behind the face that pushed it). Either way the
/// contact set flips from one iteration to the next and the iterations never settle.
///
/// A vertex whose contacts reverse (summed normals opposed to the iteration before's), or that
/// lost a face it is still behind, keeps every body contact it has had since the iteration
/// before, for the rest of the step: held between both surfaces, it settles where their
/// repulsions balance, as cloth pinched between thighs does. Where a vertex's contacts do
/// neither within a step (sheets on balls and tables do not), the contact set is the
/// detector's.
#[derive(Debug, Clone, Default)]
pub(super) struct PinchHold {
    /// Summed unit normals of each vertex's body contacts at the last iteration (zero: none).
    last_normal: Vec<Vector3<f64>>,
    /// The same at this iteration (a buffer kept between iterations and steps).
    normal: Vec<Vector3<f64>>,
    /// Held vertices and their contacts, one per face.
    held: std::collections::BTreeMap<u32, Vec<Contact>>,
}

/// The outward unit normal of a body contact's face (`None` for other contacts and slivers).
fn obstacle_normal(c: &Contact) -> Option<(u32, Vector3<f64>)> {
    match c {
        Contact::VertexObstacle { v, tri, .. } => (tri[1] - tri[0])
            .cross(&(tri[2] - tri[0]))
            .try_normalize(0.0)
            .map(|n| (*v, n)),
        _ => None,
    }
}

/// A body contact's vertex and (collider, triangle).
fn vertex_face(c: &Contact) -> Option<(u32, [u32; 2])> {
    match c {
        Contact::VertexObstacle { v, face, .. } => Some((*v, *face)),
        _ => None,
    }
}

impl PinchHold {
    /// Empties the hold for a step of a cloth of `n` vertices, keeping its buffers.
    pub(super) fn start(&mut self, n: usize) {
        self.last_normal.clear();
        self.last_normal.resize(n, Vector3::zeros());
        self.held.clear();
    }

    /// Takes the detector's `contacts` at `x`, `last` the contacts of the iteration before (as
    /// this returned them): marks the vertices whose body contacts reversed or were lost
    /// since, and adds to `contacts` the held contacts of every marked vertex that the
    /// detector did not find again. Returns how many vertices are held.
    pub(super) fn apply(
        &mut self,
        x: &[Vector3<f64>],
        last: &[Contact],
        contacts: &mut Vec<Contact>,
    ) -> usize {
        use std::collections::HashSet;
        let n = self.last_normal.len();
        let mut normal = std::mem::take(&mut self.normal);
        normal.clear();
        normal.resize(n, Vector3::zeros());
        for (v, nrm) in contacts.iter().filter_map(obstacle_normal) {
            if let Some(s) = normal.get_mut(v as usize) {
                *s += nrm;
            }
        }
        let mut marked: Vec<u32> = Vec::new();
        for (i, (now, before)) in normal.iter().zip(&self.last_normal).enumerate() {
            if now.dot(before) < 0.0 && !self.held.contains_key(&(i as u32)) {
                marked.push(i as u32);
            }
        }
        // Faces of the last iteration the vertex is still behind (inside by their reckoning).
        let held = &self.held;
        let behind: Vec<(u32, [u32; 2])> = last
            .par_iter()
            .filter_map(|c| {
                let (v, f) = vertex_face(c)?;
                (!held.contains_key(&v) && c.distance(x) < 0.0).then_some((v, f))
            })
            .collect();
        if !behind.is_empty() {
            let candidates: HashSet<u32> = behind.iter().map(|b| b.0).collect();
            let now: HashSet<(u32, [u32; 2])> = contacts
                .iter()
                .filter_map(vertex_face)
                .filter(|(v, _)| candidates.contains(v))
                .collect();
            marked.extend(behind.iter().filter(|b| !now.contains(b)).map(|b| b.0));
        }
        for v in marked {
            self.held.entry(v).or_default();
        }
        self.normal = std::mem::replace(&mut self.last_normal, normal);
        if self.held.is_empty() {
            return 0;
        }
        for c in last.iter().chain(contacts.iter()) {
            let Some((v, f)) = vertex_face(c) else {
                continue;
            };
            if let Some(list) = self.held.get_mut(&v) {
                if !list.iter().any(|h| vertex_face(h) == Some((v, f))) {
                    list.push(c.clone());
                }
            }
        }
        let found: HashSet<(u32, [u32; 2])> = contacts
            .iter()
            .filter_map(vertex_face)
            .filter(|(v, _)| self.held.contains_key(v))
            .collect();
        for list in self.held.values() {
            for c in list {
                if vertex_face(c).is_some_and(|k| !found.contains(&k)) {
                    contacts.push(c.clone());
                }
            }
        }
        self.held.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A body contact of vertex `v` with triangle `t` of a horizontal face at height `y`,
    /// facing up (`up`) or down.
    fn floor(v: u32, t: u32, y: f64, up: bool) -> Contact {
        let (a, b, c) = (
            Vector3::new(-1.0, y, -1.0),
            Vector3::new(1.0, y, -1.0),
            Vector3::new(0.0, y, 1.0),
        );
        // Counter-clockwise seen from the side the normal points to.
        let tri = if up { [a, c, b] } else { [a, b, c] };
        Contact::VertexObstacle {
            v,
            tri,
            face: [0, t],
        }
    }

    fn faces(contacts: &[Contact], v: u32) -> Vec<u32> {
        let mut f: Vec<u32> = contacts
            .iter()
            .filter_map(vertex_face)
            .filter(|k| k.0 == v)
            .map(|k| k.1[1])
            .collect();
        f.sort_unstable();
        f
    }

    #[test]
    fn only_vertices_whose_contacts_reverse_or_are_lost_while_behind_them_are_held() {
        // Vertex 0 is pushed up by face 1 (it is 2 mm below it), then the detector pushes it
        // down by face 2: reversed. Vertex 1 is 1 mm below face 3, which the detector then
        // loses: still behind it. Vertex 2 left face 4 (now 1 mm above it). Vertex 3 keeps
        // face 5.
        let x = vec![
            Vector3::new(0.0, -0.002, 0.0),
            Vector3::new(0.0, -0.001, 0.0),
            Vector3::new(0.0, 0.001, 0.0),
            Vector3::new(0.0, 0.0005, 0.0),
        ];
        let first = vec![
            floor(0, 1, 0.0, true),
            floor(1, 3, 0.0, true),
            floor(2, 4, 0.0, true),
            floor(3, 5, 0.0, true),
        ];
        let mut hold = PinchHold::default();
        hold.start(4);
        let mut found = first.clone();
        assert_eq!(hold.apply(&x, &[], &mut found), 0);
        assert_eq!(found, first);

        let mut found = vec![floor(0, 2, -0.004, false), floor(3, 5, 0.0, true)];
        assert_eq!(hold.apply(&x, &first, &mut found), 2);
        assert_eq!(faces(&found, 0), [1, 2]);
        assert_eq!(faces(&found, 1), [3]);
        assert_eq!(faces(&found, 2), Vec::<u32>::new());
        assert_eq!(faces(&found, 3), [5]);
        assert_eq!(found.len(), 4);

        // Held for the rest of the step: a face found later is added to the held ones, and
        // nothing is doubled when the detector finds a held face again.
        let last = found.clone();
        let mut found = vec![floor(0, 1, 0.0, true), floor(1, 6, 0.001, true)];
        assert_eq!(hold.apply(&x, &last, &mut found), 2);
        assert_eq!(faces(&found, 0), [1, 2]);
        assert_eq!(faces(&found, 1), [3, 6]);
        assert_eq!(found.len(), 4);

        // A new step starts with nothing held.
        let mut found = vec![floor(3, 5, 0.0, true)];
        hold.start(4);
        assert_eq!(hold.apply(&x, &[], &mut found), 0);
        assert_eq!(found.len(), 1);
    }
}
