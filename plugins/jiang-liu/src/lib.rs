//! The thermodynamic contact law of Jiang & Liu (work in progress).

use talus_contact::LawRegistry;

/// Registers the laws of this plugin.
pub fn register(_registry: &mut LawRegistry) {}
