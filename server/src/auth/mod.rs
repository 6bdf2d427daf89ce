//! Who is calling and what they may do (issue 19): secrets (API tokens,
//! sign-in sessions, passwords), the credentials every `/api/v1` request
//! must carry, and the roles that open a project's resources.

pub mod access;
pub mod accounts;
pub mod caller;
pub mod openapi;
pub mod password;
pub mod secret;

pub use access::{Role, new_resource_project, require_role};
pub use caller::{Caller, authenticate};
