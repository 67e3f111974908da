//! Schemas that a derive cannot state: enumerations whose values come
//! from elsewhere.

use utoipa::openapi::{Array, ArrayBuilder, Object, ObjectBuilder, schema::Type};

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
