//! glTF animations to clips, bound to a character's nodes.

use gltf::json::{
    animation::{Interpolation as JsonInterpolation, Property as JsonProperty},
    validation::Checked,
};

use super::{ImportError, accessor::Accessors, document::Document};
use crate::{
    import::limits::Limits,
    rig::clip::{Channel, Clip, Interpolation, Property},
    rig::skeleton::Skeleton,
};

/// Output numbers allowed per allowed keyframe over a whole file: a cubic
/// rotation key has 12; weights of many morph targets need the budget.
const NUMBERS_PER_KEY: u64 = 12;

/// Reads every animation of `doc`. `bind` maps a node of the document to
/// the character's node (identity for the character's own file, by name for
/// a clip file); channels whose node has no match are dropped with a
/// warning.
pub(crate) fn read_clips(
    doc: &Document,
    skeleton: &Skeleton,
    bind: &dyn Fn(usize) -> Option<usize>,
    limits: &Limits,
    warnings: &mut Vec<String>,
) -> Result<Vec<Clip>, ImportError> {
    let root = &doc.root;
    let animations = root.animations.len() as u64;
    if animations > limits.max_animations {
        return Err(ImportError::limit(
            "animation count",
            animations,
            limits.max_animations,
        ));
    }
    let acc = Accessors::new(doc, limits);
    let mut non_unit = 0usize;
    // Every channel decodes its sampler, so keys are counted per channel.
    let mut keys = 0u64;
    for animation in &root.animations {
        for channel in &animation.channels {
            if let Some(sampler) = animation.samplers.get(channel.sampler.value()) {
                keys = keys.saturating_add(acc.count(sampler.input.value())?);
            }
        }
    }
    if keys > limits.max_keyframes {
        return Err(ImportError::limit(
            "keyframe count",
            keys,
            limits.max_keyframes,
        ));
    }

    let mut numbers_left = limits.max_keyframes.saturating_mul(NUMBERS_PER_KEY);
    let mut clips: Vec<Clip> = Vec::with_capacity(root.animations.len());
    let mut names = std::collections::HashSet::with_capacity(root.animations.len());
    let mut unbound = 0usize;
    for (a, animation) in root.animations.iter().enumerate() {
        let mut channels = Vec::with_capacity(animation.channels.len());
        for (c, channel) in animation.channels.iter().enumerate() {
            let path = format!("animations[{a}].channels[{c}]");
            let sampler = animation
                .samplers
                .get(channel.sampler.value())
                .ok_or_else(|| {
                    ImportError::invalid(format!("{path}.sampler"), "sampler does not exist")
                })?;
            let spath = format!("animations[{a}].samplers[{}]", channel.sampler.value());
            let property = match channel.target.path {
                Checked::Valid(JsonProperty::Translation) => Property::Translation,
                Checked::Valid(JsonProperty::Rotation) => Property::Rotation,
                Checked::Valid(JsonProperty::Scale) => Property::Scale,
                Checked::Valid(JsonProperty::MorphTargetWeights) => Property::Weights,
                Checked::Invalid => {
                    return Err(ImportError::invalid(
                        format!("{path}.target.path"),
                        "unknown path",
                    ));
                }
            };
            let interpolation = match sampler.interpolation {
                Checked::Valid(JsonInterpolation::Step) => Interpolation::Step,
                Checked::Valid(JsonInterpolation::Linear) => Interpolation::Linear,
                Checked::Valid(JsonInterpolation::CubicSpline) => Interpolation::CubicSpline,
                Checked::Invalid => {
                    return Err(ImportError::invalid(
                        format!("{spath}.interpolation"),
                        "unknown interpolation",
                    ));
                }
            };
            // gltf-json's validation skips channel targets.
            let target = channel.target.node.value();
            if target >= root.nodes.len() {
                return Err(ImportError::invalid(
                    format!("{path}.target.node"),
                    format!("node {target} does not exist"),
                ));
            }
            let Some(node) = bind(target) else {
                unbound += 1;
                continue;
            };
            let width = match property {
                Property::Translation | Property::Scale => 3,
                Property::Rotation => 4,
                Property::Weights => skeleton.nodes[node].morph_weights.len(),
            };
            if width == 0 {
                warnings.push(format!(
                    "{path} animates morph weights of a node without morph targets; ignored"
                ));
                continue;
            }
            let times = acc.floats(sampler.input.value(), limits.max_keyframes)?;
            if times.width != 1 || times.values.is_empty() {
                return Err(ImportError::invalid(
                    format!("{spath}.input"),
                    "must be a non-empty SCALAR accessor of key times",
                ));
            }
            if let Some(k) = times.values.windows(2).position(|w| w[1] <= w[0]) {
                return Err(ImportError::invalid(
                    format!("{spath}.input"),
                    format!(
                        "key times must strictly increase: key {} is {} after key {} at {}",
                        k + 1,
                        times.values[k + 1],
                        k,
                        times.values[k]
                    ),
                ));
            }
            if let Some(k) = times
                .values
                .iter()
                .position(|&t| t < 0.0 || t > limits.max_clip_seconds)
            {
                return Err(ImportError::invalid(
                    format!("{spath}.input"),
                    format!(
                        "key {k} is at {} s, outside 0..={} s",
                        times.values[k], limits.max_clip_seconds
                    ),
                ));
            }
            let per_key = if interpolation == Interpolation::CubicSpline {
                3
            } else {
                1
            };
            let numbers = times.values.len() * per_key * width;
            // Weights are scalars (one per target); other outputs have one
            // element per value. The exact count bounds the allocation.
            let elements = if property == Property::Weights {
                numbers
            } else {
                numbers / width
            };
            numbers_left = numbers_left.checked_sub(numbers as u64).ok_or_else(|| {
                ImportError::limit(
                    "animation output values",
                    numbers as u64,
                    limits.max_keyframes.saturating_mul(NUMBERS_PER_KEY),
                )
            })?;
            let declared = acc.count(sampler.output.value())?;
            if declared != elements as u64 {
                return Err(ImportError::invalid(
                    format!("{spath}.output"),
                    format!(
                        "has {declared} elements; {} keys of {property:?} with {interpolation:?} need {elements}",
                        times.values.len()
                    ),
                ));
            }
            let values = acc.floats(sampler.output.value(), elements as u64)?;
            if values.values.len() != numbers {
                return Err(ImportError::invalid(
                    format!("{spath}.output"),
                    format!("has {} numbers, {numbers} needed", values.values.len()),
                ));
            }
            let mut values = values;
            if property == Property::Rotation {
                // Value keys (not tangents) must be rotations; normalised
                // here so that slerp sees unit quaternions.
                for (k, q) in values.values.chunks_exact_mut(4).enumerate() {
                    if per_key == 3 && k % 3 != 1 {
                        continue;
                    }
                    let quat = glam::Quat::from_slice(q);
                    let length = quat.length();
                    if !(length > 1e-6 && length.is_finite()) {
                        return Err(ImportError::invalid(
                            format!("{spath}.output"),
                            format!(
                                "rotation key {} is not a rotation (length {length})",
                                k / per_key
                            ),
                        ));
                    }
                    non_unit += usize::from((length - 1.0).abs() > 5e-4);
                    q.copy_from_slice(&(quat / length).to_array());
                }
            }
            channels.push(Channel {
                node,
                property,
                interpolation,
                times: times.values,
                values: values.values,
                width,
            });
        }
        let mut name = animation
            .name
            .clone()
            .filter(|n| !n.is_empty())
            .unwrap_or_else(|| format!("animation_{a}"));
        if names.contains(&name) {
            // `walk_3` may itself be taken (by a clip of that name, or an
            // earlier renaming): the first free `_3`, `_3_3`, … .
            let mut unique = format!("{name}_{a}");
            while names.contains(&unique) {
                unique = format!("{unique}_{a}");
            }
            warnings.push(format!(
                "animations[{a}]: name {name:?} is used twice; this one is {unique:?}"
            ));
            name = unique;
        }
        names.insert(name.clone());
        let duration = channels
            .iter()
            .filter_map(|c| c.times.last().copied())
            .fold(0.0f32, f32::max);
        clips.push(Clip {
            name,
            channels,
            duration,
        });
    }
    if unbound > 0 {
        warnings.push(format!(
            "{unbound} animation channels target nodes that the character does not have; ignored"
        ));
    }
    if non_unit > 0 {
        warnings.push(format!(
            "{non_unit} rotation keys were not unit quaternions; normalised"
        ));
    }
    warnings.extend(acc.bounds_warning());
    Ok(clips)
}
