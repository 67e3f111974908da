//! The texel methods' run-time AO on the GPU: a texel model's basis
//! textures ([`TexelModel::basis`]) in an R16Float array texture, one
//! layer per weight, a linear sampler and the pose's weights in a uniform
//! (`shaders/wgsl/common/texel_ao.wgsl`, bindings 3 to 5 of group 0).
//! The preview renderer samples it per pixel of the character
//! ([`super::PreviewRenderer`]); [`TexelAo::evaluate`] draws
//! `texel_ao.wgsl` over the whole atlas and reads it back, so that tests
//! compare the shader with the CPU.

use aobake_core::method::texel::TexelModel;
use aobake_shaders::{TEXEL_AO, TEXEL_MAX_LAYERS, TexelProbe, TexelWeights};
use wgpu::util::DeviceExt as _;

use super::{ErrorScopes, Gpu, GpuError};

// The runtime's bound on a texel model's textures is the shader's.
const _: () = assert!(
    aobake_core::method::texel::MAX_TEXTURES == TEXEL_MAX_LAYERS as usize,
    "the runtime's MAX_TEXTURES is texel_ao.wgsl's TEXEL_MAX_LAYERS"
);

/// The sampled format of the basis and truth textures: filterable on
/// every adapter (f32 is not without a feature), and exact for the
/// asset's f16 coefficients.
pub(crate) const FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R16Float;

/// A texel model's textures and weights on one [`Gpu`].
#[derive(Debug)]
pub struct TexelAo<'g> {
    gpu: &'g Gpu,
    /// Layers: the model's weights.
    layers: u32,
    /// The atlas's size in texels.
    size: (u32, u32),
    basis: wgpu::TextureView,
    sampler: wgpu::Sampler,
    weights: wgpu::Buffer,
}

/// `values` as f16 bits, for an [`FORMAT`] texture.
pub(crate) fn f16_bits(values: &[f32]) -> Vec<u16> {
    values
        .iter()
        .map(|&v| half::f16::from_f32(v).to_bits())
        .collect()
}

/// An R16Float texture of `layers` layers of `size`, filled with `texels`
/// (layer-major, rows within layers), sampled by the shaders.
pub(crate) fn float_texture(
    gpu: &Gpu,
    label: &str,
    (width, height): (u32, u32),
    layers: u32,
    texels: &[u16],
    usage: wgpu::TextureUsages,
) -> wgpu::Texture {
    gpu.device.create_texture_with_data(
        &gpu.queue,
        &wgpu::TextureDescriptor {
            label: Some(label),
            size: wgpu::Extent3d {
                width,
                height,
                depth_or_array_layers: layers,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: FORMAT,
            usage: usage | wgpu::TextureUsages::TEXTURE_BINDING,
            view_formats: &[],
        },
        wgpu::util::TextureDataOrder::LayerMajor,
        bytemuck::cast_slice(texels),
    )
}

impl<'g> TexelAo<'g> {
    /// Uploads `model`'s basis textures. Refused when the model has none
    /// (sparse or clustered columns), more layers than
    /// [`TEXEL_MAX_LAYERS`] or the adapter's array limit, or an atlas
    /// larger than the adapter's textures.
    pub fn new(gpu: &'g Gpu, model: &TexelModel) -> Result<Self, GpuError> {
        let basis = model
            .basis()
            .map_err(|e| GpuError::TooLarge(e.to_string()))?;
        let limits = gpu.device.limits();
        let layers = basis.len() as u32;
        if basis.len() > TEXEL_MAX_LAYERS as usize || layers > limits.max_texture_array_layers {
            return Err(GpuError::TooLarge(format!(
                "{} basis textures, more than the {} layers a texel model may have here",
                basis.len(),
                TEXEL_MAX_LAYERS.min(limits.max_texture_array_layers)
            )));
        }
        let size = (model.atlas.width, model.atlas.height);
        if size.0.max(size.1) > limits.max_texture_dimension_2d {
            return Err(GpuError::TooLarge(format!(
                "an atlas of {} × {} texels, larger than the adapter's textures",
                size.0, size.1
            )));
        }
        let device = &gpu.device;
        let scope = ErrorScopes::push(device);
        // An array of one layer at least: a model of no weights reads 0.
        let texels: Vec<u16> = if basis.is_empty() {
            vec![0; (size.0 * size.1) as usize]
        } else {
            basis.iter().flat_map(|layer| f16_bits(layer)).collect()
        };
        let texture = float_texture(
            gpu,
            "texel basis",
            size,
            layers.max(1),
            &texels,
            wgpu::TextureUsages::empty(),
        );
        let basis = texture.create_view(&wgpu::TextureViewDescriptor {
            dimension: Some(wgpu::TextureViewDimension::D2Array),
            ..Default::default()
        });
        let weights = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("texel weights"),
            contents: bytemuck::bytes_of(&TexelWeights::new(&[]).expect("no weights fit")),
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        });
        let sampler = sampler(gpu);
        if let Some(e) = scope.pop() {
            return Err(GpuError::Pipeline(e.to_string()));
        }
        Ok(Self {
            gpu,
            layers,
            size,
            basis,
            sampler,
            weights,
        })
    }

    /// Layers (the model's weights).
    pub fn layers(&self) -> u32 {
        self.layers
    }

    /// Writes a pose's weights (one per layer) for the next submission.
    pub fn write_weights(&self, weights: &[f32]) -> Result<(), GpuError> {
        if weights.len() != self.layers as usize {
            return Err(GpuError::TooLarge(format!(
                "{} weights for a texel model of {} layers",
                weights.len(),
                self.layers
            )));
        }
        let uniform = TexelWeights::new(weights)
            .ok_or_else(|| GpuError::TooLarge(format!("{} weights are too many", weights.len())))?;
        self.gpu
            .queue
            .write_buffer(&self.weights, 0, bytemuck::bytes_of(&uniform));
        Ok(())
    }

    /// Bindings 3 (basis), 4 (sampler) and 5 (weights) of group 0.
    pub(crate) fn entries(&self) -> [wgpu::BindGroupEntry<'_>; 3] {
        [
            wgpu::BindGroupEntry {
                binding: 3,
                resource: wgpu::BindingResource::TextureView(&self.basis),
            },
            wgpu::BindGroupEntry {
                binding: 4,
                resource: wgpu::BindingResource::Sampler(&self.sampler),
            },
            wgpu::BindGroupEntry {
                binding: 5,
                resource: self.weights.as_entire_binding(),
            },
        ]
    }

    /// The AO `texel_ao.wgsl` computes over the whole atlas for a pose's
    /// `weights`, at each texel centre moved by `offset` texels (0: the
    /// centres themselves), row-major, read back from an R32Float target.
    pub fn evaluate(&self, weights: &[f32], offset: [f32; 2]) -> Result<Vec<f32>, GpuError> {
        self.write_weights(weights)?;
        let gpu = self.gpu;
        let device = &gpu.device;
        let scope = ErrorScopes::push(device);
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("texel_ao.wgsl"),
            source: wgpu::ShaderSource::Wgsl(TEXEL_AO.into()),
        });
        let target_format = wgpu::TextureFormat::R32Float;
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("texel_ao"),
            layout: None,
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs_main"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            primitive: wgpu::PrimitiveState::default(),
            depth_stencil: None,
            multisample: wgpu::MultisampleState::default(),
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs_main"),
                compilation_options: Default::default(),
                targets: &[Some(target_format.into())],
            }),
            multiview_mask: None,
            cache: None,
        });
        let (width, height) = self.size;
        let probe = TexelProbe {
            size: [width as f32, height as f32],
            offset,
        };
        let probe = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("texel probe"),
            contents: bytemuck::bytes_of(&probe),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let mut entries = vec![wgpu::BindGroupEntry {
            binding: 0,
            resource: probe.as_entire_binding(),
        }];
        entries.extend(self.entries());
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("texel_ao"),
            layout: &pipeline.get_bind_group_layout(0),
            entries: &entries,
        });
        let bytes = gpu.draw_and_read(
            "texel_ao",
            &pipeline,
            &group,
            target_format,
            (width, height),
            wgpu::Color::TRANSPARENT,
            0..3,
        );
        if let Some(e) = scope.pop() {
            return Err(GpuError::Pipeline(e.to_string()));
        }
        Ok(bytemuck::pod_collect_to_vec::<u8, f32>(&bytes?))
    }
}

/// Linear filtering, clamped to the edge: how engines sample the
/// textures (aobake_runtime's `bilinear` on the CPU).
pub(crate) fn sampler(gpu: &Gpu) -> wgpu::Sampler {
    gpu.device.create_sampler(&wgpu::SamplerDescriptor {
        label: Some("texel"),
        mag_filter: wgpu::FilterMode::Linear,
        min_filter: wgpu::FilterMode::Linear,
        ..Default::default()
    })
}
