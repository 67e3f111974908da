//! What the OpenAPI document needs beyond the types' derives: enumerations
//! whose values come from elsewhere, the digest that names everything, and
//! the refusals every authenticated operation may answer.

use utoipa::openapi::{
    Array, ArrayBuilder, Object, ObjectBuilder, RefOr,
    schema::{Schema, Type},
};

/// The method names, from core's list.
pub fn method() -> Object {
    ObjectBuilder::new()
        .schema_type(Type::String)
        .enum_values(Some(
            aobake_core::method::Method::ALL.map(|m| m.name()).to_vec(),
        ))
        .description(Some("The method"))
        .build()
}

/// Token scopes.
pub fn scopes() -> Array {
    ArrayBuilder::new()
        .items(
            ObjectBuilder::new()
                .schema_type(Type::String)
                .enum_values(Some(crate::Scope::ALL.map(crate::Scope::name))),
        )
        .min_items(Some(1))
        .build()
}

/// A sha256 digest in lower-case hex: how uploads, blobs, assets and bake
/// keys are named.
#[derive(Debug)]
pub struct Digest;

impl utoipa::PartialSchema for Digest {
    fn schema() -> RefOr<Schema> {
        ObjectBuilder::new()
            .schema_type(Type::String)
            .pattern(Some("^[0-9a-f]{64}$"))
            .description(Some("sha256, lower-case hex"))
            .into()
    }
}

impl utoipa::ToSchema for Digest {}

/// What every authenticated operation may answer besides its own
/// responses: a malformed request, a missing or unknown token, a token
/// without the scope, too many requests, a database that does not answer.
#[derive(Debug, utoipa::IntoResponses)]
pub enum Refusals {
    /// Bad request.
    #[response(
        status = 400,
        description = "Bad request",
        content_type = "application/problem+json"
    )]
    BadRequest(crate::Problem),
    /// No or unknown token.
    #[response(
        status = 401,
        description = "No or unknown token, or one that expired (code token_expired, the detail says when)",
        content_type = "application/problem+json",
        headers(("WWW-Authenticate" = String, description = "`Bearer realm=\"aobake\"`"))
    )]
    Unauthorized(crate::Problem),
    /// The token lacks the scope.
    #[response(
        status = 403,
        description = "The token lacks the scope",
        content_type = "application/problem+json"
    )]
    Forbidden(crate::Problem),
    /// Too many requests.
    #[response(
        status = 429,
        description = "Too many requests",
        content_type = "application/problem+json",
        headers(("Retry-After" = u64, description = "Seconds to wait before trying again"))
    )]
    RateLimited(crate::Problem),
    /// The database or the blob store does not answer (`Retry-After` says
    /// when to try again).
    #[response(
        status = 503,
        description = "The database or the blob store does not answer; retry after Retry-After seconds",
        content_type = "application/problem+json",
        headers(("Retry-After" = u64, description = "Seconds to wait before trying again"))
    )]
    Unavailable(crate::Problem),
}
