//! Allocation problems solved entirely in the core (the general optimisers live in the Python
//! package): the separable problem of a decoupled network (the start of Newton's method) and,
//! for small networks, Newton's method with the exact Hessian in one call.

pub mod newton;
pub mod separable;

pub use newton::{newton_exact, NewtonAllocation};
pub use separable::{separable_allocation, SeparableAllocation};
