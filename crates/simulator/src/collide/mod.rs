//! Collision detection and quadratic repulsion (the paper's §4.4.4: "BVH collision detection
//! with quadratic repulsion (body and self)").
//!
//! * [`bvh`]: axis-aligned boxes and a linear BVH (Karras 2012) with refit, box, nearest and pair
//!   queries;
//! * [`distance`]: exact point–triangle and segment–segment closest points (Ericson 2005);
//! * [`repulsion`]: E = ½ κ (d̂ − d)² for d < d̂ with exact distance derivatives per
//!   closest-feature case and a Gauss-Newton (PSD) Hessian;
//! * this module: the [`Contact`] set the solver consumes and its detection
//!   ([`find_contacts`], [`CollisionDetector`]).
//!
//! # Contacts
//!
//! * **Obstacles** (cloth vertex against collider faces, counter-clockwise seen from outside):
//!   each cloth vertex is first classified inside/outside a collider like a signed distance
//!   field: the nearest collider face is found among the faces within d̂ (a BVH ball query)
//!   or, when there is none, by a BVH branch-and-bound nearest query up to
//!   [`OBSTACLE_SEARCH_M`]; the sign of (p − q)·N at the closest point q uses the
//!   angle-weighted pseudo-normal N of the faces that tie for nearest (Bærentzen & Aanæs,
//!   "Signed distance computation using the angle weighted pseudonormal", IEEE TVCG 2005), so the
//!   sign is right at edges and vertices too. An *outside* vertex gets a contact with every face
//!   within d̂ whose plane it is above (n·(p − a) ≥ 0). An *inside* vertex (penetration depth
//!   δ = distance to the nearest face) gets a contact with every face within δ + d̂ that it
//!   projects into and is below: the signed distance is then negative and the repulsion pushes
//!   it out along +n. Near a sharp edge those faces can be the wrong ones: a vertex that came
//!   in through a table's top within a step's travel of its edge is near the side too, or
//!   nearer it. When the detector knows where the vertex began the step and the collider held
//!   still ([`CollisionDetector::find_contacts_since`]), the last face its path from there
//!   went in through (the entry face) decides: faces at more than [`SHARP_EDGE_DEG`] to it get
//!   no contact, and when the nearest face is one of those, depth and reach are measured from
//!   the entry face's plane, so the vertex goes back out the way it came (if no face in line
//!   with the entry lies over it, the rule above holds). Where every face within reach lies
//!   within that angle of the entry face (a finely tessellated smooth body) nothing changes;
//!   against a moving body the rule above holds, as the path would have to be taken in the
//!   body's frame. Vertices deeper than [`OBSTACLE_SEARCH_M`] are not found (and not pushed).
//!   Only cloth vertices are tested against collider faces (no collider-vertex/edge against
//!   cloth face/edge contacts).
//! * **Creases** (cloth edge against a collider's sharp edge, faces at more than
//!   [`SHARP_EDGE_DEG`]; [`CollisionDetector::crease_contacts`]): an edge closer than d̂ to a
//!   crease, so a box's edge cannot slice between two cloth vertices. One-sided like the
//!   vertex contacts: an edge whose closest point to the crease lies behind both faces of a
//!   convex crease (or either face of a concave one) has crossed it and gets no contact, as
//!   the unsigned distance would otherwise hold it there from inside. The side is judged at
//!   the positions detected, not along the step: an edge the solver's first guess carries past
//!   a crease is released, not pushed back (vertices have the entry-face rule for that). The
//!   simulator gives these contacts friction (a sheet grips the edge it wraps over).
//! * **Self** (cloth against cloth, unsigned distance): vertex–triangle pairs (vertex not in the
//!   triangle) and edge–edge pairs (no shared vertex) closer than d̂, found with a BVH over the
//!   triangles inflated by d̂ (point queries) and a BVH over the edges inflated by d̂/2 (self
//!   pairs). d̂ must stay well below the cloth's edge lengths: elements of the same flat patch that
//!   share no vertex but are closer than d̂ at rest would repel.
//!
//! The contact set is fixed while the solver iterates; [`Contact::energy_gradient_hessian`]
//! re-evaluates the distance (and its closest features) at the solver's current positions.

pub mod bvh;
pub mod distance;
pub mod repulsion;

mod body;
mod contact;
mod crease;
mod crossings;
mod detector;
mod inside;
mod self_contacts;
#[cfg(test)]
mod tests;

pub use contact::{find_contacts, Collider, CollisionParams, Contact, StepStart};
pub use crease::{sharp_edges, SHARP_EDGE_DEG};
pub use crossings::edge_triangle_crossings;
pub use detector::{ClothPairs, CollisionDetector, SURFACE_TURN_DEG};
pub use inside::{count_inside, max_penetration, push_out, PushOut};

/// How deep (metres) a cloth vertex may be inside a collider and still be found and pushed out;
/// also the search radius of [`max_penetration`]. Never less than d̂ in detection.
pub const OBSTACLE_SEARCH_M: f64 = 0.05;
