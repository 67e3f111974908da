//! The C ABI as C sees it: the checked-in header is what cbindgen makes of
//! the crate now, and a C program compiled against it plays a baked asset
//! through the shared library with the same numbers as the Rust runtime.

use std::{
    alloc::{GlobalAlloc, Layout, System},
    cell::Cell,
    path::{Path, PathBuf},
    process::Command,
};

use aobake_core::{
    Limits, Pose, Upload,
    bake::{Bake, BakeInputs, BakeParams, bake_in_process},
    import_character,
    method::Method,
};
use aobake_rt::AOBAKE_RT_ABI_VERSION;
use aobake_runtime::method::vertex::VertexAo;

/// The system allocator, counting each thread's allocations (calls and
/// bytes), so that a test measures what one call allocates.
struct Counting;

thread_local! {
    static ALLOCATED: Cell<(usize, usize)> = const { Cell::new((0, 0)) };
}

fn count(bytes: usize) {
    // Not counted while the thread is being torn down.
    let _ = ALLOCATED.try_with(|a| {
        let (calls, total) = a.get();
        a.set((calls + 1, total + bytes));
    });
}

// SAFETY: every call is forwarded to the system allocator unchanged.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count(layout.size());
        // SAFETY: forwarded from the caller.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        count(layout.size());
        // SAFETY: forwarded from the caller.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count(new_size);
        // SAFETY: forwarded from the caller.
        unsafe { System.realloc(ptr, layout, new_size) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded from the caller.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// What `f` allocated on this thread: calls and bytes.
fn allocated(f: impl FnOnce()) -> (usize, usize) {
    let before = ALLOCATED.with(Cell::get);
    f();
    let after = ALLOCATED.with(Cell::get);
    (after.0 - before.0, after.1 - before.1)
}

fn crate_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn the_header_is_what_cbindgen_generates() {
    let mut generated = Vec::new();
    cbindgen::generate(crate_dir())
        .expect("cbindgen reads the crate")
        .write(&mut generated);
    let path = crate_dir().join("include/aobake_rt.h");
    if std::env::var_os("AOBAKE_BLESS").is_some() {
        std::fs::write(&path, &generated).unwrap();
    }
    let checked_in = std::fs::read(&path).unwrap_or_default();
    assert!(
        checked_in == generated,
        "include/aobake_rt.h is stale: AOBAKE_BLESS=1 cargo test -p aobake-runtime-capi rewrites it"
    );
}

/// The folder with the shared library: the test binary's own (target/…/deps).
fn library_dir() -> PathBuf {
    let exe = std::env::current_exe().unwrap();
    let deps = exe.parent().unwrap().to_path_buf();
    assert!(
        deps.join("libaobake_rt.so").is_file(),
        "the cdylib is built beside the tests in {}",
        deps.display()
    );
    deps
}

fn bake_rigged_figure(method: Method) -> (Vec<u8>, aobake_core::Character, Vec<aobake_core::Clip>) {
    let mut params = BakeParams::new(method);
    params.poses = 96;
    params.samples = 64;
    params.eval_poses = 8;
    params.eval_fps = 15.0;
    bake("RiggedFigure", params)
}

/// Grid parameters for a bake of seconds: 4³ cells, few rays, one
/// evaluation frame.
fn tiny_grid() -> BakeParams {
    let mut params = BakeParams::new(Method::Grid);
    params.grid.resolution = 4;
    params.grid.rays = 8;
    params.grid.eval_frames = 1;
    params.grid.eval_rays = 8;
    params.grid.eval_ground = 8;
    params
}

/// A bundled character baked in process with `params`: the asset, the
/// character and its clips.
fn bake(
    name: &str,
    params: BakeParams,
) -> (Vec<u8>, aobake_core::Character, Vec<aobake_core::Clip>) {
    let path = crate_dir().join(format!("../../tests/data/characters/{name}/{name}.glb"));
    let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let imported = import_character(Upload::single(&bytes), &Limits::default()).unwrap();
    let inputs = BakeInputs {
        character: imported.character.clone(),
        clips: imported.clips.clone(),
        character_digest: "character-digest".into(),
        clip_digests: Vec::new(),
        warnings: Vec::new(),
    };
    let baked = bake_in_process(&Bake::new(&inputs, params).unwrap(), None).unwrap();
    (baked.asset, imported.character, imported.clips)
}

/// The library installed as docs/engines.md says, in `dir`:
/// `libaobake_rt.so.N` (its SONAME) and the `libaobake_rt.so` link that
/// `-laobake_rt` finds.
fn install(dir: &Path) -> PathBuf {
    let lib = dir.to_path_buf();
    let _ = std::fs::remove_dir_all(&lib);
    std::fs::create_dir_all(&lib).unwrap();
    let versioned = format!("libaobake_rt.so.{AOBAKE_RT_ABI_VERSION}");
    std::fs::copy(library_dir().join("libaobake_rt.so"), lib.join(&versioned)).unwrap();
    std::os::unix::fs::symlink(&versioned, lib.join("libaobake_rt.so")).unwrap();
    lib
}

/// The library's SONAME carries its ABI version, so a program linked
/// against it loads only a library of that ABI.
#[test]
fn the_library_is_named_by_its_abi() {
    let out = Command::new("readelf")
        .arg("-d")
        .arg(library_dir().join("libaobake_rt.so"))
        .output()
        .expect("readelf (binutils, with the C compiler)");
    let text = String::from_utf8_lossy(&out.stdout);
    let soname = text
        .lines()
        .find(|l| l.contains("(SONAME)"))
        .unwrap_or_else(|| panic!("no SONAME: {text}"));
    assert!(
        soname.ends_with(&format!("[libaobake_rt.so.{AOBAKE_RT_ABI_VERSION}]")),
        "{soname}"
    );
}

fn compile(dir: &Path, program: &str) -> PathBuf {
    let exe = dir.join(program);
    let lib = install(&dir.join(format!("lib-{program}")));
    let status = Command::new(std::env::var("CC").unwrap_or_else(|_| "cc".into()))
        .args(["-std=c99", "-Wall", "-Wextra", "-Werror", "-I"])
        .arg(crate_dir().join("include"))
        .arg(crate_dir().join(format!("tests/c/{program}.c")))
        .arg("-L")
        .arg(&lib)
        .arg(format!("-Wl,-rpath,{}", lib.display()))
        .arg("-laobake_rt")
        .arg("-o")
        .arg(&exe)
        .status()
        .expect("a C compiler (cc)");
    assert!(status.success(), "{program}.c compiles against the header");
    // Linked against the SONAME: it loads only a library of its ABI.
    let out = Command::new("readelf")
        .arg("-d")
        .arg(&exe)
        .output()
        .unwrap();
    let needed = format!("Shared library: [libaobake_rt.so.{AOBAKE_RT_ABI_VERSION}]");
    assert!(
        String::from_utf8_lossy(&out.stdout).contains(&needed),
        "{program} does not need {needed}: {}",
        String::from_utf8_lossy(&out.stdout)
    );
    exe
}

/// A pose as the C programs read it: a line per node, its name, a tab,
/// then translation, rotation (x y z w) and scale as Rust's shortest
/// round-trip floats, which C's strtof reads back exactly.
fn pose_text(character: &aobake_core::Character, pose: &Pose) -> String {
    let mut text = String::new();
    for (node, t) in character.skeleton.nodes.iter().zip(&pose.locals) {
        let name = node
            .name
            .as_deref()
            .expect("the test characters name their nodes");
        let numbers: Vec<String> = t
            .translation
            .to_array()
            .iter()
            .chain(&t.rotation.to_array())
            .chain(&t.scale.to_array())
            .map(|x| format!("{x:e}"))
            .collect();
        text.push_str(&format!("{name}\t{}\n", numbers.join(" ")));
    }
    text
}

#[test]
fn a_c_program_plays_an_asset_as_the_runtime_does() {
    let dir = std::env::temp_dir().join(format!("aobake-capi-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let exe = compile(&dir, "play");
    for method in [Method::VertexLinear, Method::VertexClustered] {
        let (asset, character, clips) = bake_rigged_figure(method);
        let asset_path = dir.join("figure.aobake");
        std::fs::write(&asset_path, &asset).unwrap();
        // A frame of the clip, every node by name, as an engine's
        // animation gives it: Rust's shortest round-trip floats, which C's
        // strtof reads back exactly.
        let pose = Pose::sample(&character.skeleton, &clips[0], 0.7);
        let pose_path = dir.join("pose.txt");
        std::fs::write(&pose_path, pose_text(&character, &pose)).unwrap();
        let floats = run_c(&exe, &[&asset_path, &pose_path], &dir.join("out.bin"));
        let mut rust = VertexAo::from_bytes(&asset).unwrap();
        for (n, t) in pose.locals.iter().enumerate() {
            assert!(rust.set_local(n, *t));
        }
        let (weights, ao) = floats.split_at(rust.weight_count());
        assert_eq!(weights, rust.weights(), "{method:?}: weights bit for bit");
        assert_eq!(ao, rust.evaluate(), "{method:?}: AO bit for bit");
        assert!(ao.iter().any(|&a| a > 0.0), "{method:?}: some occlusion");
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// A C program plays a texel asset: its pose through the vertex
/// functions on `aobake_texel_pose`'s handle, the weights, the AO sampled
/// at the atlas's UVs and a basis texture bit for bit as the Rust runtime
/// gives them.
#[test]
fn a_c_program_plays_a_texel_asset_as_the_runtime_does() {
    use aobake_runtime::{Asset, method::texel::bilinear};
    let dir = std::env::temp_dir().join(format!("aobake-capi-texel-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let exe = compile(&dir, "texel");
    let mut params = BakeParams::new(Method::TexelLinear);
    params.poses = 48;
    params.samples = 16;
    params.eval_poses = 4;
    params.texel.atlas = 64;
    let (asset, character, clips) = bake("RiggedFigure", params);
    let asset_path = dir.join("figure.aobake");
    std::fs::write(&asset_path, &asset).unwrap();
    let pose = Pose::sample(&character.skeleton, &clips[0], 0.7);
    let pose_path = dir.join("pose.txt");
    std::fs::write(&pose_path, pose_text(&character, &pose)).unwrap();
    let floats = run_c(&exe, &[&asset_path, &pose_path], &dir.join("out.bin"));

    let Asset::Texel { model, header } = Asset::from_bytes(&asset).unwrap() else {
        panic!("a texel asset");
    };
    let mut rust = VertexAo::new(model.model.clone(), *header).unwrap();
    for (n, t) in pose.locals.iter().enumerate() {
        assert!(rust.set_local(n, *t));
    }
    let w = rust.weights();
    let a = &model.atlas;
    let (weights, rest) = floats.split_at(w.len());
    let (ao, basis) = rest.split_at(a.xref.len());
    assert_eq!(weights, w, "weights bit for bit");
    let image = model.texture(&w).unwrap();
    let want: Vec<f32> = a
        .uvs
        .iter()
        .map(|&uv| bilinear(&image, a.width, a.height, uv).clamp(0.0, 1.0))
        .collect();
    assert_eq!(ao, want, "the AO at the atlas's UVs bit for bit");
    assert!(ao.iter().any(|&x| x > 0.05), "some occlusion");
    assert_eq!(basis, model.basis().unwrap()[0], "the first basis texture");
    std::fs::remove_dir_all(&dir).ok();
}

/// An engine lists the rig to map its bones onto: every node's name and
/// parent as the asset's rig has them, and the name finds the node again.
#[test]
fn the_rig_is_listed_by_name_and_parent() {
    use aobake_rt::{
        aobake_last_error, aobake_vertex_ao_free, aobake_vertex_ao_node,
        aobake_vertex_ao_node_count, aobake_vertex_ao_node_name, aobake_vertex_ao_node_parent,
        aobake_vertex_ao_open,
    };
    use std::ffi::CStr;
    let (asset, character, _) = bake_rigged_figure(Method::VertexLinear);
    // SAFETY: `asset` holds `len` readable bytes.
    let ao = unsafe { aobake_vertex_ao_open(asset.as_ptr(), asset.len()) };
    assert!(!ao.is_null());
    // SAFETY: a live handle.
    let count = unsafe { aobake_vertex_ao_node_count(ao) };
    assert_eq!(count, character.skeleton.nodes.len());
    for (n, node) in character.skeleton.nodes.iter().enumerate() {
        // SAFETY: a live handle; the name lives as long as it.
        let name = unsafe { CStr::from_ptr(aobake_vertex_ao_node_name(ao, n)) };
        let name = name.to_str().unwrap();
        assert_eq!(Some(name), node.name.as_deref(), "node {n}");
        let mut parent = -7i64;
        // SAFETY: a live handle and a writable i64.
        assert!(unsafe { aobake_vertex_ao_node_parent(ao, n, &mut parent) });
        assert_eq!(parent, node.parent.map_or(-1, |p| p as i64), "node {n}");
        let again = std::ffi::CString::new(name).unwrap();
        // SAFETY: a live handle and a NUL-terminated name.
        let found = unsafe { aobake_vertex_ao_node(ao, again.as_ptr()) };
        assert_eq!(found, n as i64);
    }
    // Past the rig: NULL and false, and the error says why.
    // SAFETY: a live handle.
    assert!(unsafe { aobake_vertex_ao_node_name(ao, count) }.is_null());
    // SAFETY: the library's last error, a NUL-terminated string.
    let why = unsafe { CStr::from_ptr(aobake_last_error()) };
    assert_eq!(why.to_str().unwrap(), format!("node {count} of {count}"));
    let mut parent = 0i64;
    // SAFETY: a live handle and a writable i64.
    assert!(!unsafe { aobake_vertex_ao_node_parent(ao, count, &mut parent) });
    assert_eq!(parent, 0, "nothing written");
    // SAFETY: a live handle, freed once.
    unsafe { aobake_vertex_ao_free(ao) };
}

/// A player's frame allocates nothing: once a handle has computed a pose,
/// `aobake_vertex_ao_weights` and `aobake_vertex_ao_evaluate` of the next
/// pose (set node by node) touch no heap, and both give the runtime's
/// numbers.
#[test]
fn a_frame_allocates_nothing_after_the_first() {
    use aobake_rt::{
        AobakeTransform, aobake_vertex_ao_evaluate, aobake_vertex_ao_free, aobake_vertex_ao_open,
        aobake_vertex_ao_set_local, aobake_vertex_ao_vertices, aobake_vertex_ao_weight_count,
        aobake_vertex_ao_weights,
    };
    for method in [Method::VertexLinear, Method::VertexClustered] {
        let (asset, character, clips) = bake_rigged_figure(method);
        // SAFETY: `asset` holds `len` readable bytes.
        let ao = unsafe { aobake_vertex_ao_open(asset.as_ptr(), asset.len()) };
        assert!(!ao.is_null());
        // SAFETY: a live handle.
        let (vertices, count) = unsafe {
            (
                aobake_vertex_ao_vertices(ao),
                aobake_vertex_ao_weight_count(ao),
            )
        };
        let (mut values, mut weights) = (vec![0.0f32; vertices], vec![0.0f32; count]);
        let frame = |time: f32, weights: &mut [f32], values: &mut [f32]| {
            let pose = Pose::sample(&character.skeleton, &clips[0], time);
            let locals: Vec<AobakeTransform> = pose.locals.iter().map(|&t| t.into()).collect();
            let counted = allocated(|| {
                for (n, t) in locals.iter().enumerate() {
                    // SAFETY: a live handle and a readable transform.
                    assert!(unsafe { aobake_vertex_ao_set_local(ao, n, t) });
                }
                // SAFETY: a live handle and `count` writable floats.
                assert!(unsafe { aobake_vertex_ao_weights(ao, weights.as_mut_ptr(), count) });
                // SAFETY: a live handle and `vertices` writable floats.
                assert!(unsafe { aobake_vertex_ao_evaluate(ao, values.as_mut_ptr(), vertices) });
            });
            (pose, counted)
        };
        let (_, first) = frame(0.2, &mut weights, &mut values);
        assert!(first.0 > 0, "{method:?}: the first frame sizes the buffers");
        let (pose, next) = frame(0.7, &mut weights, &mut values);
        assert_eq!(
            next,
            (0, 0),
            "{method:?}: a later frame allocates (calls, bytes)"
        );
        let mut rust = VertexAo::from_bytes(&asset).unwrap();
        for (n, t) in pose.locals.iter().enumerate() {
            assert!(rust.set_local(n, *t));
        }
        assert_eq!(weights, rust.weights(), "{method:?}: weights bit for bit");
        assert_eq!(values, rust.evaluate(), "{method:?}: AO bit for bit");
        // SAFETY: a live handle, freed once.
        unsafe { aobake_vertex_ao_free(ao) };
    }
}

/// Runs `exe` with `args` on the library it was built with; the floats it
/// wrote to `out`.
fn run_c(exe: &Path, args: &[&Path], out: &Path) -> Vec<f32> {
    // cargo's LD_LIBRARY_PATH would put target/debug first, where an older
    // build's copy of the library may lie: the rpath decides.
    let run = Command::new(exe)
        .env_remove("LD_LIBRARY_PATH")
        .args(args)
        .arg(out)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}{}",
        String::from_utf8_lossy(&run.stdout),
        String::from_utf8_lossy(&run.stderr)
    );
    std::fs::read(out)
        .unwrap()
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
        .collect()
}

/// Raw words written among floats.
fn words(floats: &[f32]) -> Vec<u32> {
    floats.iter().map(|x| x.to_bits()).collect()
}

/// Receivers as lookups.c reads them: `px py pz nx ny nz part kind` a
/// line.
fn receivers_text(receivers: &[(glam::Vec3, glam::Vec3, i64, i64)]) -> String {
    receivers
        .iter()
        .map(|(p, n, k, kind)| {
            format!(
                "{:e} {:e} {:e} {:e} {:e} {:e} {k} {kind}\n",
                p.x, p.y, p.z, n.x, n.y, n.z
            )
        })
        .collect()
}

#[test]
fn c_programs_look_up_cubemaps_and_grids_as_the_runtime_does() {
    use aobake_runtime::method::{
        cubemap::{CubemapModel, gpu::CubemapGpu},
        grid::{
            base::Receiver,
            gpu::GridGpu,
            model::{GridModel, Terms},
        },
    };
    use glam::Vec3;

    let dir = std::env::temp_dir().join(format!("aobake-capi-lookups-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let exe = compile(&dir, "lookups");
    let receivers_path = dir.join("receivers.txt");
    let asset_path = dir.join("asset.aob");
    let out_path = dir.join("out.bin");

    // A small cubemap of CesiumMan's walk; receivers around it and below.
    let mut params = BakeParams::new(Method::CubemapDiscrete);
    params.samples = 16;
    params.cubemap.resolution = 8;
    params.cubemap.times = 16;
    params.cubemap.eval_times = 2;
    let (asset, _, _) = bake("CesiumMan", params);
    std::fs::write(&asset_path, &asset).unwrap();
    let container = aobake_runtime::Container::from_bytes(&asset).unwrap();
    let (model, _) = CubemapModel::from_container(&container).unwrap();
    let s = model.layout.spheroid;
    let receivers: Vec<(Vec3, Vec3, i64, i64)> = (0..64)
        .map(|i| {
            let t = i as f32 / 63.0;
            let d = Vec3::new((7.0 * t).cos(), 2.0 * t - 1.0, (7.0 * t).sin());
            (s.centre + s.radii * d * (0.6 + 0.8 * t), Vec3::Y, -1, -1)
        })
        .collect();
    std::fs::write(&receivers_path, receivers_text(&receivers)).unwrap();
    let seconds = 0.7f32;
    let c = run_c(
        &exe,
        &[
            Path::new("cubemap"),
            &asset_path,
            Path::new(&seconds.to_string()),
            &receivers_path,
        ],
        &out_path,
    );
    let phase = model.layout.phase(seconds);
    assert!(model.ground.is_some(), "a static ground by default");
    let rust: Vec<f32> = receivers
        .iter()
        .map(|(p, _, _, _)| model.occlusion(*p, phase))
        .chain(
            receivers
                .iter()
                .map(|(p, _, _, _)| model.ground_ao(*p, phase)),
        )
        .collect();
    let (c, gpu_words) = c.split_at(rust.len());
    assert_eq!(c, rust, "cubemap lookups bit for bit");
    // Then the GPU form as the runtime packs it, and the phase.
    let gpu = CubemapGpu::new(&model).unwrap();
    // The params byte for byte as the shaders' uniform (the fields of a
    // dispatch at 0).
    let uniform = aobake_shaders::mirror::CubemapAoParams {
        centre: gpu.centre,
        radii: gpu.radii,
        resolution: gpu.resolution,
        shells: gpu.shells,
        times: gpu.times,
        encoding: gpu.encoding,
        points: 0,
        phase: 0.0,
        row_stride: 0,
        on_ground: 0,
    };
    let expected: Vec<u32> = bytemuck::cast_slice::<u8, u32>(bytemuck::bytes_of(&uniform))
        .iter()
        .copied()
        .chain([phase.to_bits()])
        .chain(gpu.texels.iter().copied())
        .chain(gpu.ground.iter().copied())
        .collect();
    assert!(gpu.ground.len() > 5, "the static ground's texture");
    assert_eq!(words(gpu_words), expected, "the cubemap's GPU form");
    assert_ne!(
        c[..64],
        c[64..],
        "the static ground changes the ground's AO"
    );
    assert!(rust.iter().any(|&a| a > 0.0), "some occlusion");

    // Small grids of the milk truck's parts, posed at a frame of its clip.
    let mut params = BakeParams::new(Method::Grid);
    params.grid.resolution = 8;
    params.grid.rays = 32;
    params.grid.eval_frames = 2;
    params.grid.eval_rays = 16;
    params.grid.eval_ground = 16;
    params.grid.average_frames = 2;
    let (asset, character, clips) = bake("CesiumMilkTruck", params);
    std::fs::write(&asset_path, &asset).unwrap();
    let container = aobake_runtime::Container::from_bytes(&asset).unwrap();
    let (model, _) = GridModel::from_container(&container).unwrap();
    let palette = character.joint_matrices(&Pose::sample(&character.skeleton, &clips[0], 0.4));
    let palette_text: String = palette
        .iter()
        .map(|m| {
            let n: Vec<String> = m.to_cols_array().iter().map(|x| format!("{x:e}")).collect();
            n.join(" ") + "\n"
        })
        .collect();
    let palette_path = dir.join("palette.txt");
    std::fs::write(&palette_path, palette_text).unwrap();
    let poses = model.poses(&palette);
    let base = model.base.as_ref().expect("the default grid has a base");
    assert!(base.vertex_offsets.iter().any(|&o| o != 0.0));
    // Receivers at each part's grid centre (on that part, facing up, as
    // vertex k), on the ground below it and beside that (on no part).
    let mut receivers = Vec::new();
    for (k, pose) in poses.iter().enumerate() {
        let centre = pose
            .grid_from_world
            .inverse()
            .transform_point3(Vec3::splat(0.5));
        receivers.push((centre, Vec3::Y, k as i64, k as i64));
        receivers.push((centre - Vec3::Y * 0.5, Vec3::Y, -1, -1));
        receivers.push((centre - Vec3::Y * 0.5, Vec3::X, -1, -2));
    }
    std::fs::write(&receivers_path, receivers_text(&receivers)).unwrap();
    let c = run_c(
        &exe,
        &[
            Path::new("grid"),
            &asset_path,
            &palette_path,
            &receivers_path,
        ],
        &out_path,
    );
    let grids = receivers
        .iter()
        .map(|(p, n, k, _)| model.occlusion(&poses, *p, *n, usize::try_from(*k).ok(), Terms::All));
    let on_base = receivers.iter().map(|&(p, n, k, kind)| {
        let receiver = match kind {
            -1 => Receiver::Ground,
            -2 => Receiver::Other {
                part: usize::try_from(k).ok(),
            },
            index => Receiver::Vertex {
                index: index as usize,
                part: usize::try_from(k).ok(),
            },
        };
        model.ao(&poses, p, n, receiver)
    });
    let rust: Vec<f32> = grids.chain(on_base).collect();
    let (c, gpu_words) = c.split_at(rust.len());
    assert_eq!(c, rust, "grid lookups bit for bit");
    // Then the GPU form as the runtime packs it, each part's joint, the
    // base's offsets and ground, and the frame's poses.
    let gpu = GridGpu::new(&model).unwrap();
    let uniform = aobake_shaders::mirror::GridAoParams {
        parts: gpu.parts(),
        points: 0,
        row_stride: 0,
        cones: gpu.cones,
        tclip_resolution: gpu.tclip_resolution,
        tclip_offset: gpu.tclip_offset,
        base: gpu.base,
        ground_gain: gpu.ground_gain,
    };
    let mut expected: Vec<u32> = bytemuck::cast_slice(bytemuck::bytes_of(&uniform)).to_vec();
    for part in &model.parts {
        let joint = part.joint as u64;
        expected.extend([joint as u32, (joint >> 32) as u32]);
    }
    expected.extend(gpu.infos.as_flattened());
    expected.extend(&gpu.cells);
    expected.extend(base.vertex_offsets.iter().map(|x| x.to_bits()));
    expected.extend(base.ground.gpu_words());
    for pose in &poses {
        let matrices = [pose.grid_from_world, pose.world_from_bind];
        expected.extend(
            matrices
                .iter()
                .flat_map(|m| m.to_cols_array().map(f32::to_bits)),
        );
    }
    assert_eq!(words(gpu_words), expected, "the grid's GPU form");
    assert!(rust.iter().any(|&a| a > 0.0), "some occlusion");
    std::fs::remove_dir_all(&dir).ok();
}

/// `aobake_vertex_ao_gpu_words` hands a C engine the arrays the GPU
/// evaluators read (the runtime's `GpuArrays`), sized by a first call;
/// dense and sparse models, and the refusals.
#[test]
fn the_gpu_arrays_reach_c_as_the_runtime_packs_them() {
    use aobake_rt::{
        AOBAKE_GPU_BLOCKS, AOBAKE_GPU_COEFFICIENTS, AOBAKE_GPU_MAPS, AOBAKE_GPU_SPARSE_ROWS,
        AobakeVertexGpuParams, AobakeVertexVsParams, aobake_last_error, aobake_vertex_ao_free,
        aobake_vertex_ao_gpu_params, aobake_vertex_ao_gpu_sparse, aobake_vertex_ao_gpu_words,
        aobake_vertex_ao_open, aobake_vertex_ao_vs_params,
    };
    use aobake_runtime::method::vertex::form::GpuArrays;
    let mut sparse_params = BakeParams::new(Method::VertexLinear);
    sparse_params.poses = 48;
    sparse_params.samples = 16;
    sparse_params.eval_poses = 2;
    sparse_params.linear.threshold = 0.01;
    let assets = [
        bake_rigged_figure(Method::VertexClustered).0,
        bake("RiggedFigure", sparse_params).0,
    ];
    let last_error = || {
        let e = aobake_last_error();
        assert!(!e.is_null());
        // SAFETY: not NULL: a C string valid until the next failing call.
        unsafe { std::ffi::CStr::from_ptr(e) }
            .to_string_lossy()
            .into_owned()
    };
    let mut kinds = Vec::new();
    for asset in &assets {
        let want = GpuArrays::new(VertexAo::from_bytes(asset).unwrap().model().form()).unwrap();
        kinds.push(want.sparse);
        // SAFETY: `asset` holds `len` readable bytes.
        let ao = unsafe { aobake_vertex_ao_open(asset.as_ptr(), asset.len()) };
        assert!(!ao.is_null());
        // SAFETY: a live handle.
        assert_eq!(unsafe { aobake_vertex_ao_gpu_sparse(ao) }, want.sparse);
        // The uniforms byte for byte as the shaders' (their engine fields
        // at 0).
        let mut params = std::mem::MaybeUninit::<AobakeVertexGpuParams>::zeroed();
        let mut vs = std::mem::MaybeUninit::<AobakeVertexVsParams>::zeroed();
        // SAFETY: a live handle and writable structs.
        assert!(unsafe { aobake_vertex_ao_gpu_params(ao, params.as_mut_ptr()) });
        // SAFETY: likewise.
        assert!(unsafe { aobake_vertex_ao_vs_params(ao, vs.as_mut_ptr()) });
        // SAFETY: both were written whole above.
        let (params, vs) = unsafe { (params.assume_init(), vs.assume_init()) };
        let uniform = aobake_shaders::mirror::VertexAoParams {
            vertices: want.vertices,
            blocks: want.blocks.len() as u32,
            row_stride: 0,
            _pad: 0,
        };
        let vs_uniform = aobake_shaders::mirror::VertexAoVsParams {
            vertices: want.vertices,
            blocks: want.blocks.len() as u32,
            sparse: u32::from(want.sparse),
            width: 0,
            target_width: 0,
            target_height: 0,
            _pad: [0; 2],
        };
        // SAFETY: plain repr(C) structs of u32s, read as their bytes.
        let bytes_of =
            |p: *const u8, n: usize| unsafe { std::slice::from_raw_parts(p, n) }.to_vec();
        assert_eq!(
            bytes_of(
                (&raw const params).cast(),
                size_of::<AobakeVertexGpuParams>()
            ),
            bytemuck::bytes_of(&uniform)
        );
        assert_eq!(
            bytes_of((&raw const vs).cast(), size_of::<AobakeVertexVsParams>()),
            bytemuck::bytes_of(&vs_uniform)
        );
        // Every array has a word at least: an unused one is one word of 0.
        let blocks = match want.blocks.concat() {
            b if b.is_empty() => vec![0],
            b => b,
        };
        for (which, expected) in [
            (AOBAKE_GPU_BLOCKS, blocks),
            (AOBAKE_GPU_COEFFICIENTS, want.coefficients.clone()),
            (AOBAKE_GPU_MAPS, want.maps.clone()),
            (AOBAKE_GPU_SPARSE_ROWS, want.sparse_rows.clone()),
        ] {
            let mut words = usize::MAX;
            // SAFETY: a live handle, NULL out, a writable `words`.
            let sized = unsafe {
                aobake_vertex_ao_gpu_words(ao, which, std::ptr::null_mut(), 0, &mut words)
            };
            assert!(sized && words == expected.len(), "array {which}");
            let mut out = vec![0u32; words];
            // SAFETY: `out` holds `words` writable words.
            let copied = unsafe {
                aobake_vertex_ao_gpu_words(ao, which, out.as_mut_ptr(), out.len(), &mut words)
            };
            assert!(copied && out == expected, "array {which}");
            if words > 0 {
                // SAFETY: one word fewer than the array is writable.
                let short = unsafe {
                    aobake_vertex_ao_gpu_words(ao, which, out.as_mut_ptr(), words - 1, &mut words)
                };
                assert!(!short && last_error().contains("out holds"));
            }
        }
        let mut words = 0;
        // SAFETY: a live handle, NULL out, a writable `words`.
        let unknown =
            unsafe { aobake_vertex_ao_gpu_words(ao, 9, std::ptr::null_mut(), 0, &mut words) };
        assert!(!unknown && last_error().contains("array 9"));
        // SAFETY: a live handle, freed once.
        unsafe { aobake_vertex_ao_free(ao) };
    }
    assert_eq!(kinds, [false, true], "one dense model and one sparse");
}

/// The cubemap's and grid's GPU forms refuse a NULL handle, an unknown
/// array and a short buffer with the reason, and describe an asset baked
/// without a static ground or base as the shaders expect it: a ground
/// of one word (0) and no vertex offsets.
#[test]
fn the_volume_gpu_forms_refuse_what_is_wrong_and_say_when_there_is_no_base() {
    use aobake_rt::{
        AOBAKE_CUBEMAP_GPU_GROUND, AOBAKE_CUBEMAP_GPU_TEXELS, AOBAKE_GRID_GPU_GROUND,
        AOBAKE_GRID_GPU_INFOS, AOBAKE_GRID_GPU_VERTEX_OFFSETS, AobakeCubemapGpuParams,
        AobakeGridGpuParams, aobake_cubemap_free, aobake_cubemap_gpu_params,
        aobake_cubemap_gpu_words, aobake_cubemap_open, aobake_grid_free, aobake_grid_gpu_params,
        aobake_grid_gpu_poses, aobake_grid_gpu_words, aobake_grid_open, aobake_grid_part_count,
        aobake_last_error,
    };
    let last_error = || {
        // SAFETY: not NULL after a failing call: a C string valid until
        // the next failing call.
        unsafe { std::ffi::CStr::from_ptr(aobake_last_error()) }
            .to_string_lossy()
            .into_owned()
    };
    let null_cubemap = std::ptr::null();
    let null_grid = std::ptr::null();
    let mut words = 0usize;
    // SAFETY: NULL handles are allowed; `words` is writable.
    unsafe {
        let mut cp = std::mem::zeroed::<AobakeCubemapGpuParams>();
        assert!(!aobake_cubemap_gpu_params(null_cubemap, &mut cp));
        assert!(last_error().contains("NULL"));
        assert!(!aobake_cubemap_gpu_words(
            null_cubemap,
            0,
            std::ptr::null_mut(),
            0,
            &mut words
        ));
        let mut gp = std::mem::zeroed::<AobakeGridGpuParams>();
        assert!(!aobake_grid_gpu_params(null_grid, &mut gp));
        assert!(!aobake_grid_gpu_words(
            null_grid,
            0,
            std::ptr::null_mut(),
            0,
            &mut words
        ));
        assert!(last_error().contains("NULL"));
    }

    let mut params = BakeParams::new(Method::CubemapDiscrete);
    params.samples = 8;
    params.cubemap.resolution = 4;
    params.cubemap.times = 8;
    params.cubemap.eval_times = 1;
    params.cubemap.static_ground = false;
    let (asset, _, _) = bake("CesiumMan", params);
    // SAFETY: `asset` holds `len` readable bytes; the handle is live
    // until freed at the end; `out` holds what each call is told.
    unsafe {
        let c = aobake_cubemap_open(asset.as_ptr(), asset.len());
        assert!(!c.is_null(), "{}", last_error());
        let mut ground = [9u32; 4];
        assert!(aobake_cubemap_gpu_words(
            c,
            AOBAKE_CUBEMAP_GPU_GROUND,
            ground.as_mut_ptr(),
            ground.len(),
            &mut words
        ));
        assert_eq!((words, ground[0]), (1, 0), "no static ground: one word, 0");
        assert!(aobake_cubemap_gpu_words(
            c,
            AOBAKE_CUBEMAP_GPU_TEXELS,
            std::ptr::null_mut(),
            0,
            &mut words
        ));
        let mut short = vec![0u32; words - 1];
        assert!(!aobake_cubemap_gpu_words(
            c,
            AOBAKE_CUBEMAP_GPU_TEXELS,
            short.as_mut_ptr(),
            short.len(),
            &mut words
        ));
        assert!(last_error().contains("out holds"), "{}", last_error());
        assert!(!aobake_cubemap_gpu_words(
            c,
            2,
            std::ptr::null_mut(),
            0,
            &mut words
        ));
        assert!(last_error().contains("array 2"), "{}", last_error());
        aobake_cubemap_free(c);
    }

    let mut params = tiny_grid();
    params.grid.static_base = false;
    let (asset, character, clips) = bake("CesiumMilkTruck", params);
    let palette: Vec<f32> = character
        .joint_matrices(&Pose::sample(&character.skeleton, &clips[0], 0.2))
        .iter()
        .flat_map(|m| m.to_cols_array())
        .collect();
    // SAFETY: as above; `palette` holds 16 floats a matrix.
    unsafe {
        let g = aobake_grid_open(asset.as_ptr(), asset.len());
        assert!(!g.is_null(), "{}", last_error());
        let mut gp = std::mem::zeroed::<AobakeGridGpuParams>();
        assert!(aobake_grid_gpu_params(g, &mut gp));
        assert_eq!((gp.base, gp.ground_gain), (0, 0.0), "no static base");
        assert!(aobake_grid_gpu_words(
            g,
            AOBAKE_GRID_GPU_VERTEX_OFFSETS,
            std::ptr::null_mut(),
            0,
            &mut words
        ));
        assert_eq!(words, 0, "no vertex offsets without a base");
        let mut ground = [9u32; 2];
        assert!(aobake_grid_gpu_words(
            g,
            AOBAKE_GRID_GPU_GROUND,
            ground.as_mut_ptr(),
            ground.len(),
            &mut words
        ));
        assert_eq!((words, ground[0]), (1, 0), "no ground texture: one word, 0");
        let mut infos = vec![0u32; 4 * aobake_grid_part_count(g) - 1];
        assert!(!aobake_grid_gpu_words(
            g,
            AOBAKE_GRID_GPU_INFOS,
            infos.as_mut_ptr(),
            infos.len(),
            &mut words
        ));
        assert_eq!(words, infos.len() + 1, "sized even when refused");
        assert!(!aobake_grid_gpu_words(
            g,
            4,
            std::ptr::null_mut(),
            0,
            &mut words
        ));
        assert!(last_error().contains("array 4"), "{}", last_error());
        let parts = aobake_grid_part_count(g);
        let mut poses = vec![0f32; 32 * parts + 1];
        assert!(!aobake_grid_gpu_poses(
            g,
            palette.as_ptr(),
            palette.len() / 16,
            poses.as_mut_ptr(),
            poses.len()
        ));
        assert!(last_error().contains("poses"), "{}", last_error());
        assert!(aobake_grid_gpu_poses(
            g,
            palette.as_ptr(),
            palette.len() / 16,
            poses.as_mut_ptr(),
            32 * parts
        ));
        aobake_grid_free(g);
    }
}

/// What a C engine needs beside the lookups: each grid part's node name
/// (to fill the palette), the ground planes' heights, and refusals of a
/// time or a normal that means nothing; a normal of another length is
/// normalised.
#[test]
fn c_engines_get_part_names_and_ground_heights_and_bad_input_is_refused() {
    use aobake_rt::{
        aobake_cubemap_free, aobake_cubemap_ground_height, aobake_cubemap_occlusion,
        aobake_cubemap_open, aobake_grid_free, aobake_grid_ground_height, aobake_grid_occlusion,
        aobake_grid_open, aobake_grid_palette_len, aobake_grid_part_count, aobake_grid_part_joint,
        aobake_grid_part_name, aobake_last_error,
    };
    use aobake_runtime::method::{cubemap::CubemapModel, grid::model::GridModel};
    let last_error = || {
        // SAFETY: not NULL after a failing call: a C string valid until
        // the next failing call.
        unsafe { std::ffi::CStr::from_ptr(aobake_last_error()) }
            .to_string_lossy()
            .into_owned()
    };

    let mut params = BakeParams::new(Method::CubemapDiscrete);
    params.samples = 8;
    params.cubemap.resolution = 4;
    params.cubemap.times = 8;
    params.cubemap.eval_times = 1;
    let (asset, _, _) = bake("CesiumMan", params);
    let container = aobake_runtime::Container::from_bytes(&asset).unwrap();
    let (model, _) = CubemapModel::from_container(&container).unwrap();
    let height = model.ground.as_ref().unwrap().square.height;
    let point = model.layout.spheroid.centre;
    // SAFETY: `asset` holds `len` readable bytes; the handle lives until
    // freed; each buffer holds what its call is told.
    unsafe {
        let c = aobake_cubemap_open(asset.as_ptr(), asset.len());
        let mut h = f32::NAN;
        assert!(aobake_cubemap_ground_height(c, &mut h));
        assert_eq!(h, height);
        let mut out = [5.0f32];
        assert!(!aobake_cubemap_occlusion(
            c,
            f32::NAN,
            point.as_ref().as_ptr(),
            1,
            out.as_mut_ptr()
        ));
        assert!(last_error().contains("seconds"), "{}", last_error());
        assert_eq!(out, [5.0], "nothing written");
        aobake_cubemap_free(c);
    }

    let mut params = tiny_grid();
    params.grid.average_frames = 2;
    let (asset, character, clips) = bake("CesiumMilkTruck", params);
    let container = aobake_runtime::Container::from_bytes(&asset).unwrap();
    let (model, _) = GridModel::from_container(&container).unwrap();
    let matrices = character.joint_matrices(&Pose::sample(&character.skeleton, &clips[0], 0.2));
    let palette: Vec<f32> = matrices.iter().flat_map(|m| m.to_cols_array()).collect();
    let centre = model.poses(&matrices)[0]
        .grid_from_world
        .inverse()
        .transform_point3(glam::Vec3::splat(0.5));
    // SAFETY: as above.
    unsafe {
        let g = aobake_grid_open(asset.as_ptr(), asset.len());
        for (k, part) in model.parts.iter().enumerate() {
            let name = aobake_grid_part_name(g, k);
            assert!(!name.is_null());
            assert_eq!(std::ffi::CStr::from_ptr(name).to_str().unwrap(), part.name);
            assert_eq!(aobake_grid_part_joint(g, k), part.joint as i64);
            // The palette entry is that node's: the character's joint of
            // that name.
            let node = character.joints[part.joint].node;
            assert_eq!(character.skeleton.label(node), part.name);
        }
        assert!(aobake_grid_part_name(g, aobake_grid_part_count(g)).is_null());
        let mut h = f32::NAN;
        assert!(aobake_grid_ground_height(g, &mut h));
        assert_eq!(h, model.base.as_ref().unwrap().ground.square.height);
        let n = aobake_grid_palette_len(g);
        let point = [centre.x, centre.y - 0.3, centre.z];
        // The point's occlusion with `normal`, or `None` when refused.
        let look = |normal: [f32; 3]| {
            let mut out = [0f32];
            aobake_grid_occlusion(
                g,
                palette.as_ptr(),
                n,
                point.as_ptr(),
                normal.as_ptr(),
                std::ptr::null(),
                1,
                out.as_mut_ptr(),
            )
            .then_some(out[0])
        };
        let unit = look([0.0, 1.0, 0.0]).unwrap();
        assert_eq!(
            look([0.0, 3.0, 0.0]),
            Some(unit),
            "a normal of length 3 is normalised"
        );
        for y in [1e-30f32, 3e30] {
            assert_eq!(
                look([0.0, y, 0.0]),
                Some(unit),
                "a normal of length {y} is a direction"
            );
        }
        let down = look([0.0, -1.0, 0.0]).unwrap();
        assert!(
            unit > 0.0 && unit != down,
            "the normal matters: {unit:?} {down:?}"
        );
        assert_eq!(look([0.0; 3]), None);
        assert!(last_error().contains("zero length"), "{}", last_error());
        aobake_grid_free(g);
    }
}

/// A handle's `*_primitive` call, bound to it.
type GetPrimitive<'a> = dyn Fn(usize, *mut aobake_rt::AobakePrimitive) -> bool + 'a;

/// An engine that imports the glTF its own way finds each primitive's
/// vertices among the asset's: the table of a vertex asset and of a grid
/// asset is the importer's, instance by instance (the milk truck's wheel
/// mesh twice), and past it a call fails saying why.
#[test]
fn engines_map_their_vertices_by_the_primitive_table() {
    use aobake_rt::{
        AobakePrimitive, aobake_grid_free, aobake_grid_open, aobake_grid_primitive,
        aobake_grid_primitive_count, aobake_last_error, aobake_vertex_ao_free,
        aobake_vertex_ao_open, aobake_vertex_ao_primitive, aobake_vertex_ao_primitive_count,
    };
    let mut average = BakeParams::new(Method::StaticAverage);
    average.poses = 4;
    average.samples = 8;
    average.eval_poses = 1;
    average.eval_fps = 2.0;
    let (vertex, character, _) = bake("CesiumMilkTruck", average);
    let (grid, _, _) = bake("CesiumMilkTruck", tiny_grid());
    let expected: Vec<AobakePrimitive> = character
        .primitives
        .iter()
        .map(|p| AobakePrimitive {
            node: p.node,
            mesh: p.mesh,
            primitive: p.primitive,
            first: p.vertices.start,
            count: p.vertices.len(),
        })
        .collect();
    assert_eq!(
        expected.len(),
        5,
        "the body's three primitives, the wheels' one twice"
    );
    let blank = AobakePrimitive {
        node: 99,
        mesh: 99,
        primitive: 99,
        first: 99,
        count: 99,
    };
    // SAFETY: each asset holds `len` readable bytes; the handles live
    // until freed; `out` is a writable struct.
    unsafe {
        let ao = aobake_vertex_ao_open(vertex.as_ptr(), vertex.len());
        let g = aobake_grid_open(grid.as_ptr(), grid.len());
        assert!(!ao.is_null() && !g.is_null());
        let tables: [(usize, &GetPrimitive); 2] = [
            (aobake_vertex_ao_primitive_count(ao), &|i, out| {
                aobake_vertex_ao_primitive(ao, i, out)
            }),
            (aobake_grid_primitive_count(g), &|i, out| {
                aobake_grid_primitive(g, i, out)
            }),
        ];
        for (count, get) in tables {
            let mut table = Vec::new();
            for i in 0..count {
                let mut out = blank;
                assert!(get(i, &mut out));
                table.push(out);
            }
            assert_eq!(table, expected);
            let mut out = blank;
            assert!(!get(count, &mut out));
            assert_eq!(out, blank, "nothing written");
            let why = std::ffi::CStr::from_ptr(aobake_last_error());
            assert_eq!(
                why.to_str().unwrap(),
                format!("primitive {count} of {count}")
            );
            assert!(!get(0, std::ptr::null_mut()));
        }
        assert_eq!(aobake_vertex_ao_primitive_count(std::ptr::null()), 0);
        aobake_vertex_ao_free(ao);
        aobake_grid_free(g);
    }
}
