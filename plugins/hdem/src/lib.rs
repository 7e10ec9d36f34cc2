//! HDEM hysteresis rolling resistance (work in progress).

use talus_contact::{LawRegistry, SubModel};

/// Registers, for the law `name` made of normal `N`, damping `D` and tangential `T`
/// parts, the variants with the HDEM rolling part.
pub fn register_variants<N: SubModel, D: SubModel, T: SubModel>(
    _registry: &mut LawRegistry,
    _name: &'static str,
    _summary: &'static str,
) {
}
