//! glTF 2.0 rules that `gltf-json`'s validation does not check and the
//! Khronos validator reports as errors (docs/import-policy.md): formats of
//! attributes and inverse bind matrices, byte strides outside vertex
//! attributes, unique joints and roots, morph target counts, animation
//! channels, nodes with both a matrix and TRS, and integers too wide for
//! the 32-bit fields `gltf-json` truncates them into.
//!
//! Each rule refuses the file with the JSON path of the first offence;
//! problems inside images (which AO never decodes) are counted as warnings.

use std::collections::{HashMap, HashSet};

use gltf::json::{
    self, Root,
    accessor::{ComponentType, Type},
    animation::Property,
    mesh::Semantic,
    validation::Checked,
};

use super::{ImportError, error::push_member};

/// Keys whose values (a number, or an array of numbers) are indices or
/// enums, which `gltf-json` reads as 32-bit.
const NARROW_KEYS: &[&str] = &[
    "buffer",
    "bufferView",
    "byteStride",
    "camera",
    "children",
    "componentType",
    "index",
    "indices",
    "input",
    "inverseBindMatrices",
    "joints",
    "magFilter",
    "material",
    "mesh",
    "minFilter",
    "mode",
    "node",
    "nodes",
    "output",
    "sampler",
    "scene",
    "skeleton",
    "skin",
    "source",
    "target",
    "texCoord",
    "wrapS",
    "wrapT",
];

/// Refuses the first index or enum above `u32::MAX`: `gltf-json` reads
/// them as `value as u32`, so a primitive mode of 2³²+4 would silently
/// become 4 (triangles) and a mesh index of 2³² would become mesh 0.
/// Other numbers (bounds, transforms, factors) may be any size; attribute
/// and morph-target maps hold accessor indices under any name.
pub(crate) fn check_integer_widths(json: &serde_json::Value) -> Result<(), ImportError> {
    /// What the numbers at a place in the JSON are.
    #[derive(Clone, Copy, PartialEq)]
    enum Here {
        /// Any number.
        Free,
        /// Indices or enums (objects inside start over).
        Narrow,
        /// Objects mapping names to accessor indices (attributes, morph
        /// targets).
        Maps,
    }
    fn walk(value: &serde_json::Value, path: &mut String, here: Here) -> Result<(), ImportError> {
        match value {
            serde_json::Value::Number(n)
                if here == Here::Narrow && n.as_u64().is_some_and(|v| v > u64::from(u32::MAX)) =>
            {
                return Err(ImportError::invalid(
                    path.clone(),
                    format!("{n} is out of range (at most {})", u32::MAX),
                ));
            }
            serde_json::Value::Array(items) => {
                for (i, item) in items.iter().enumerate() {
                    let len = path.len();
                    path.push_str(&format!("[{i}]"));
                    walk(item, path, here)?;
                    path.truncate(len);
                }
            }
            serde_json::Value::Object(map) => {
                for (key, item) in map {
                    // Extensions and extras are free-form.
                    if key == "extras" || key == "extensions" {
                        continue;
                    }
                    let child = if here == Here::Maps {
                        Here::Narrow
                    } else if key == "attributes" || key == "targets" {
                        Here::Maps
                    } else if NARROW_KEYS.contains(&key.as_str()) {
                        Here::Narrow
                    } else {
                        Here::Free
                    };
                    let len = path.len();
                    push_member(path, key);
                    walk(item, path, child)?;
                    path.truncate(len);
                }
            }
            _ => {}
        }
        Ok(())
    }
    walk(json, &mut String::new(), Here::Free)
}

/// Checks the structural rules; returns how many problems were found in
/// images (warned about, not refused).
pub(crate) fn check(root: &Root, parents: &[Option<usize>]) -> Result<usize, ImportError> {
    nodes(root)?;
    scenes(root, parents)?;
    skins(root, parents)?;
    meshes(root)?;
    animations(root)?;
    strides(root)?;
    sparse(root)?;
    for (i, accessor) in root.accessors.iter().enumerate() {
        let small = [
            ComponentType::I8,
            ComponentType::U8,
            ComponentType::I16,
            ComponentType::U16,
        ];
        if accessor.normalized && !small.into_iter().any(|c| is(accessor, c)) {
            return Err(ImportError::invalid(
                format!("accessors[{i}].normalized"),
                "only byte and short components may be normalized",
            ));
        }
        if accessor.count.0 == 0 {
            return Err(ImportError::invalid(
                format!("accessors[{i}].count"),
                "is 0; an accessor has at least one element",
            ));
        }
    }
    Ok(images(root))
}

fn nodes(root: &Root) -> Result<(), ImportError> {
    for (n, node) in root.nodes.iter().enumerate() {
        if node.matrix.is_some()
            && (node.translation.is_some() || node.rotation.is_some() || node.scale.is_some())
        {
            return Err(ImportError::invalid(
                format!("nodes[{n}]"),
                "has both a matrix and translation, rotation or scale; a node has one or the other",
            ));
        }
        if let Some(weights) = &node.weights {
            let targets = node
                .mesh
                .and_then(|m| root.meshes.get(m.value()))
                .map_or(0, target_count);
            if weights.len() != targets {
                return Err(ImportError::invalid(
                    format!("nodes[{n}].weights"),
                    format!(
                        "has {} weights but its mesh has {targets} morph targets",
                        weights.len()
                    ),
                ));
            }
        }
    }
    Ok(())
}

fn scenes(root: &Root, parents: &[Option<usize>]) -> Result<(), ImportError> {
    for (s, scene) in root.scenes.iter().enumerate() {
        unique(
            scene.nodes.iter().map(|n| n.value()),
            &format!("scenes[{s}].nodes"),
        )?;
        for (k, node) in scene.nodes.iter().enumerate() {
            if let Some(Some(parent)) = parents.get(node.value()) {
                return Err(ImportError::invalid(
                    format!("scenes[{s}].nodes[{k}]"),
                    format!(
                        "node {} is a child of node {parent}; a scene lists only root nodes",
                        node.value()
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// Each node's tree as a depth-first interval: `enter[a] <= enter[n] <
/// exit[a]` exactly when `a` is `n` or its ancestor, and `root[n]` is its
/// tree's root. One pass over the forest (cycles and shared children were
/// refused before), so checking a skin costs one step a joint.
struct Forest {
    root: Vec<usize>,
    enter: Vec<usize>,
    exit: Vec<usize>,
}

impl Forest {
    fn new(root: &Root, parents: &[Option<usize>]) -> Self {
        let n = parents.len();
        let mut forest = Self {
            root: (0..n).collect(),
            enter: vec![0; n],
            exit: vec![0; n],
        };
        let mut clock = 0;
        for top in (0..n).filter(|&i| parents[i].is_none()) {
            // (node, whether its children were pushed)
            let mut stack = vec![(top, false)];
            while let Some((node, expanded)) = stack.pop() {
                if expanded {
                    forest.exit[node] = clock;
                    continue;
                }
                forest.root[node] = top;
                forest.enter[node] = clock;
                clock += 1;
                stack.push((node, true));
                let children = root.nodes[node].children.iter().flatten();
                stack.extend(children.map(|c| (c.value(), false)));
            }
        }
        forest
    }

    /// Whether `a` is `n` or one of its ancestors.
    fn contains(&self, a: usize, n: usize) -> bool {
        self.enter[a] <= self.enter[n] && self.enter[n] < self.exit[a]
    }
}

fn skins(root: &Root, parents: &[Option<usize>]) -> Result<(), ImportError> {
    if root.skins.is_empty() {
        return Ok(());
    }
    let forest = Forest::new(root, parents);
    for (s, skin) in root.skins.iter().enumerate() {
        let joints = || skin.joints.iter().map(|j| j.value());
        unique(joints(), &format!("skins[{s}].joints"))?;
        // SKIN_NO_COMMON_ROOT: the joints are nodes of one tree.
        if let Some(first) = joints().next()
            && let Some(other) = joints().find(|&j| forest.root[j] != forest.root[first])
        {
            return Err(ImportError::invalid(
                format!("skins[{s}].joints"),
                format!("joints {first} and {other} have no common root"),
            ));
        }
        // SKIN_SKELETON_INVALID: the skeleton is a common root of them.
        if let Some(skeleton) = skin.skeleton.map(|k| k.value())
            && let Some(joint) = joints().find(|&j| !forest.contains(skeleton, j))
        {
            return Err(ImportError::invalid(
                format!("skins[{s}].skeleton"),
                format!("node {skeleton} is not an ancestor of joint {joint}"),
            ));
        }
        if let Some(ibm) = skin.inverse_bind_matrices {
            let path = format!("skins[{s}].inverseBindMatrices");
            let accessor = accessor(root, ibm.value(), &path)?;
            if !matches!(accessor.type_, Checked::Valid(Type::Mat4))
                || !is(accessor, ComponentType::F32)
            {
                return Err(ImportError::invalid(
                    path,
                    format!("accessor {} must hold float MAT4 matrices", ibm.value()),
                ));
            }
        }
    }
    Ok(())
}

fn target_count(mesh: &json::Mesh) -> usize {
    mesh.primitives
        .first()
        .and_then(|p| p.targets.as_ref())
        .map_or(0, Vec::len)
}

fn meshes(root: &Root) -> Result<(), ImportError> {
    // Used or required (a file that requires it and forgot to list it as
    // used still means it).
    let quantized = root
        .extensions_used
        .iter()
        .chain(&root.extensions_required)
        .any(|e| e == "KHR_mesh_quantization");
    for (m, mesh) in root.meshes.iter().enumerate() {
        let targets = target_count(mesh);
        for (p, prim) in mesh.primitives.iter().enumerate() {
            let here = format!("meshes[{m}].primitives[{p}]");
            let count = prim.targets.as_ref().map_or(0, Vec::len);
            if count != targets {
                return Err(ImportError::invalid(
                    format!("{here}.targets"),
                    format!(
                        "has {count} morph targets but primitive 0 of the mesh has {targets}; \
                         every primitive of a mesh has the same number"
                    ),
                ));
            }
            for (semantic, index) in &prim.attributes {
                let Checked::Valid(semantic) = semantic else {
                    continue;
                };
                let mut path = format!("{here}.attributes");
                push_member(&mut path, &semantic.to_string());
                let accessor = accessor(root, index.value(), &path)?;
                if let Some(expected) = attribute_format(semantic, accessor, quantized) {
                    return Err(ImportError::invalid(
                        path,
                        format!("accessor {} must be {expected}", index.value()),
                    ));
                }
            }
            for (t, target) in prim.targets.iter().flatten().enumerate() {
                for (name, base, index) in [
                    ("POSITION", Semantic::Positions, target.positions),
                    ("NORMAL", Semantic::Normals, target.normals),
                    ("TANGENT", Semantic::Tangents, target.tangents),
                ] {
                    let Some(index) = index else { continue };
                    let path = format!("{here}.targets[{t}].{name}");
                    if !prim.attributes.contains_key(&Checked::Valid(base)) {
                        return Err(ImportError::invalid(
                            path,
                            format!("the primitive has no {name} for this target to displace"),
                        ));
                    }
                    let accessor = accessor(root, index.value(), &path)?;
                    let float = is(accessor, ComponentType::F32);
                    let small = [ComponentType::I8, ComponentType::I16]
                        .into_iter()
                        .any(|c| is(accessor, c));
                    if !matches!(accessor.type_, Checked::Valid(Type::Vec3))
                        || !(float || quantized && small)
                    {
                        return Err(ImportError::invalid(
                            path,
                            format!("accessor {} must be a float VEC3", index.value()),
                        ));
                    }
                }
            }
        }
        if let Some(weights) = &mesh.weights
            && weights.len() != targets
        {
            return Err(ImportError::invalid(
                format!("meshes[{m}].weights"),
                format!(
                    "has {} weights but the mesh has {targets} morph targets",
                    weights.len()
                ),
            ));
        }
    }
    Ok(())
}

/// What an attribute's accessor must be, when it is not (glTF 2.0 §3.7.2.1,
/// and KHR_mesh_quantization when the file uses it). Attributes AO does not
/// read are held to the same rules: a file that breaks them is broken.
fn attribute_format(
    semantic: &Semantic,
    accessor: &json::Accessor,
    quantized: bool,
) -> Option<&'static str> {
    use ComponentType::{F32, I8, I16, U8, U16};
    let ty = match accessor.type_ {
        Checked::Valid(ty) => ty,
        Checked::Invalid => return Some("of a known type"),
    };
    let normalized = |c: ComponentType| is(accessor, c) && accessor.normalized;
    let any = |c: ComponentType| is(accessor, c);
    let float = any(F32);
    let (types, ok, expected): (&[Type], bool, &'static str) = match semantic {
        Semantic::Positions => (
            &[Type::Vec3],
            float || quantized && [I8, U8, I16, U16].into_iter().any(any),
            "a float VEC3 (integer components need KHR_mesh_quantization)",
        ),
        Semantic::Normals => (
            &[Type::Vec3],
            float || quantized && [I8, I16].into_iter().any(normalized),
            "a float VEC3 (normalized integers need KHR_mesh_quantization)",
        ),
        Semantic::Tangents => (
            &[Type::Vec4],
            float || quantized && [I8, I16].into_iter().any(normalized),
            "a float VEC4 (normalized integers need KHR_mesh_quantization)",
        ),
        Semantic::TexCoords(_) => (
            &[Type::Vec2],
            float
                || [U8, U16].into_iter().any(normalized)
                || quantized && [I8, U8, I16, U16].into_iter().any(any),
            "a VEC2 of floats or normalized unsigned bytes or shorts",
        ),
        Semantic::Colors(_) => (
            &[Type::Vec3, Type::Vec4],
            float || [U8, U16].into_iter().any(normalized),
            "a VEC3 or VEC4 of floats or normalized unsigned bytes or shorts",
        ),
        Semantic::Joints(_) => (
            &[Type::Vec4],
            (any(U8) || any(U16)) && !accessor.normalized,
            "a VEC4 of unsigned bytes or shorts",
        ),
        Semantic::Weights(_) => (
            &[Type::Vec4],
            float || [U8, U16].into_iter().any(normalized),
            "a VEC4 of floats or normalized unsigned bytes or shorts",
        ),
        #[allow(unreachable_patterns)]
        _ => return None,
    };
    (!types.contains(&ty) || !ok).then_some(expected)
}

fn animations(root: &Root) -> Result<(), ImportError> {
    for (a, animation) in root.animations.iter().enumerate() {
        for (s, sampler) in animation.samplers.iter().enumerate() {
            let path = format!("animations[{a}].samplers[{s}].input");
            let keys = accessor(root, sampler.input.value(), &path)?.count.0;
            if matches!(
                sampler.interpolation,
                Checked::Valid(json::animation::Interpolation::CubicSpline)
            ) && keys < 2
            {
                return Err(ImportError::invalid(
                    path,
                    format!("a cubic-spline sampler needs at least 2 keys, not {keys}"),
                ));
            }
        }
        let mut targets = HashSet::new();
        for (c, channel) in animation.channels.iter().enumerate() {
            let path = format!("animations[{a}].channels[{c}].target");
            let Checked::Valid(property) = channel.target.path else {
                continue; // gltf-json's validation names it
            };
            let n = channel.target.node.value();
            if !targets.insert((n, property as u8)) {
                return Err(ImportError::invalid(
                    path,
                    format!(
                        "another channel of this animation already targets node {n}'s {property:?}"
                    ),
                ));
            }
            let Some(node) = root.nodes.get(n) else {
                continue; // gltf-json's validation names it
            };
            if property == Property::MorphTargetWeights {
                let targets = node
                    .mesh
                    .and_then(|m| root.meshes.get(m.value()))
                    .map_or(0, target_count);
                if targets == 0 {
                    return Err(ImportError::invalid(
                        path,
                        format!("animates morph weights of node {n}, which has no morph targets"),
                    ));
                }
            } else if node.matrix.is_some() {
                return Err(ImportError::invalid(
                    path,
                    format!("animates node {n}, which has a matrix; animated nodes have TRS"),
                ));
            }
        }
    }
    Ok(())
}

/// `byteStride` is for vertex attributes only: index, inverse-bind-matrix
/// and animation accessors must be tightly packed.
fn strides(root: &Root) -> Result<(), ImportError> {
    let check = |index: usize, path: String| -> Result<(), ImportError> {
        let accessor = accessor(root, index, &path)?;
        let Some(view) = accessor.buffer_view else {
            return Ok(());
        };
        if root
            .buffer_views
            .get(view.value())
            .is_some_and(|v| v.byte_stride.is_some())
        {
            return Err(ImportError::invalid(
                path,
                format!(
                    "accessor {index} lies in bufferViews[{}], which has a byteStride; \
                     only vertex attributes may be strided",
                    view.value()
                ),
            ));
        }
        Ok(())
    };
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            if let Some(indices) = prim.indices {
                check(
                    indices.value(),
                    format!("meshes[{m}].primitives[{p}].indices"),
                )?;
            }
        }
    }
    for (s, skin) in root.skins.iter().enumerate() {
        if let Some(ibm) = skin.inverse_bind_matrices {
            check(ibm.value(), format!("skins[{s}].inverseBindMatrices"))?;
        }
    }
    for (a, animation) in root.animations.iter().enumerate() {
        for (s, sampler) in animation.samplers.iter().enumerate() {
            let here = format!("animations[{a}].samplers[{s}]");
            check(sampler.input.value(), format!("{here}.input"))?;
            check(sampler.output.value(), format!("{here}.output"))?;
        }
    }
    Ok(())
}

/// A sparse part has at least one element, and its indices and values
/// lie in buffer views without a `byteStride` (the glTF schema's rules;
/// that the indices strictly increase is checked as they are read).
fn sparse(root: &Root) -> Result<(), ImportError> {
    for (i, accessor) in root.accessors.iter().enumerate() {
        let Some(sparse) = &accessor.sparse else {
            continue;
        };
        let path = format!("accessors[{i}].sparse");
        if sparse.count.0 == 0 {
            return Err(ImportError::invalid(
                format!("{path}.count"),
                "is 0; a sparse part has at least one element",
            ));
        }
        for (part, view) in [
            ("indices", sparse.indices.buffer_view.value()),
            ("values", sparse.values.buffer_view.value()),
        ] {
            if root
                .buffer_views
                .get(view)
                .is_some_and(|v| v.byte_stride.is_some())
            {
                return Err(ImportError::invalid(
                    format!("{path}.{part}"),
                    format!(
                        "lie in bufferViews[{view}], which has a byteStride; sparse parts are tightly packed"
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// Problems with images stored in buffer views, which AO never decodes
/// (images are never decoded at all): no `mimeType`, a `uri` as well, a
/// view that does not exist or is strided.
fn images(root: &Root) -> usize {
    root.images
        .iter()
        .filter(|image| match image.buffer_view {
            None => false,
            Some(view) => {
                image.mime_type.is_none()
                    || image.uri.is_some()
                    || root
                        .buffer_views
                        .get(view.value())
                        .is_none_or(|v| v.byte_stride.is_some())
            }
        })
        .count()
}

fn accessor<'r>(
    root: &'r Root,
    index: usize,
    path: &str,
) -> Result<&'r json::Accessor, ImportError> {
    root.accessors
        .get(index)
        .ok_or_else(|| ImportError::invalid(path, format!("accessor {index} does not exist")))
}

fn is(accessor: &json::Accessor, component: ComponentType) -> bool {
    matches!(accessor.component_type, Checked::Valid(json::accessor::GenericComponentType(c)) if c == component)
}

/// Refuses an entry of the list at `path` that repeats an earlier one,
/// naming the repeat (`path[k]`) and where it was first.
pub(super) fn unique(items: impl Iterator<Item = usize>, path: &str) -> Result<(), ImportError> {
    let mut seen = HashMap::new();
    for (k, item) in items.enumerate() {
        if let Some(first) = seen.insert(item, k) {
            return Err(ImportError::invalid(
                format!("{path}[{k}]"),
                format!("repeats {item} (first at [{first}]); its entries are unique"),
            ));
        }
    }
    Ok(())
}
