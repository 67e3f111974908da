//! Names the shared library by its ABI: on Linux its SONAME is
//! `libaobake_rt.so.N` for `AOBAKE_RT_ABI_VERSION` N (read from
//! src/lib.rs, the one place it is written), so a plugin linked against
//! it asks the loader for that file, and a library of another ABI is
//! never loaded in its place (docs/engines.md, "Installing").

fn main() {
    println!("cargo:rerun-if-changed=src/lib.rs");
    if std::env::var("CARGO_CFG_TARGET_OS").as_deref() != Ok("linux") {
        return;
    }
    let source = std::fs::read_to_string("src/lib.rs").expect("src/lib.rs");
    let abi: u32 = source
        .lines()
        .find_map(|l| l.strip_prefix("pub const AOBAKE_RT_ABI_VERSION: u32 = "))
        .and_then(|rest| rest.strip_suffix(';'))
        .and_then(|n| n.parse().ok())
        .expect("src/lib.rs defines AOBAKE_RT_ABI_VERSION as a u32 literal");
    println!("cargo:rustc-cdylib-link-arg=-Wl,-soname,libaobake_rt.so.{abi}");
}
