//! Build script: under the `ur-rtde` feature, compiles the C shim over ur_rtde 1.6.5
//! (`ffi/ur_rtde_shim.cpp`) and links the wheel's `librtde.so`. Without the feature it does
//! nothing.
//!
//! Inputs, set by `scripts/deps/env.sh` after `scripts/setup`:
//! - `UR_RTDE_INCLUDE`: the sdist's `include/` (holds `ur_rtde/` and `urcl/`);
//! - `UR_RTDE_LIB_DIR`: the directory of `librtde.so.1.6.5` (the PyPI wheel's site-packages);
//! - Boost's headers from Debian's `libboost-dev` (`/usr/include`).

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    #[cfg(feature = "ur-rtde")]
    ur_rtde();
}

/// Compiles the shim and links librtde (feature `ur-rtde`; `cc` is a build dependency only
/// then).
#[cfg(feature = "ur-rtde")]
fn ur_rtde() {
    println!("cargo:rerun-if-changed=ffi/ur_rtde_shim.cpp");
    println!("cargo:rerun-if-changed=ffi/ur_rtde_shim.h");
    println!("cargo:rerun-if-changed=ffi/include/ur_rtde/rtde_export.h");
    println!("cargo:rerun-if-env-changed=UR_RTDE_INCLUDE");
    println!("cargo:rerun-if-env-changed=UR_RTDE_LIB_DIR");
    println!("cargo:rerun-if-env-changed=OBJCOPY");

    let need = |var: &str| -> std::path::PathBuf {
        match std::env::var_os(var) {
            Some(v) if !v.is_empty() => std::path::PathBuf::from(v),
            _ => panic!(
                "robot-io feature `ur-rtde`: {var} is not set. Run scripts/setup (it installs \
                 ur_rtde 1.6.5's headers, the wheel's librtde.so and libboost-dev), then \
                 `source scripts/deps/env.sh`."
            ),
        }
    };
    let include = need("UR_RTDE_INCLUDE");
    let lib_dir = need("UR_RTDE_LIB_DIR");
    if !include.join("ur_rtde/rtde_receive_interface.h").is_file() {
        panic!(
            "robot-io feature `ur-rtde`: {} has no ur_rtde/rtde_receive_interface.h (UR_RTDE_INCLUDE)",
            include.display()
        );
    }
    if !lib_dir.join("librtde.so.1.6.5").is_file() {
        panic!(
            "robot-io feature `ur-rtde`: {} has no librtde.so.1.6.5 (UR_RTDE_LIB_DIR)",
            lib_dir.display()
        );
    }

    cc::Build::new()
        .cpp(true)
        .std("c++17")
        // The wheel's librtde.so is built on manylinux2014 with the old libstdc++ string ABI.
        .define("_GLIBCXX_USE_CXX11_ABI", "0")
        .include("ffi/include")
        .include("ffi")
        .include(&include)
        .warnings(false)
        .file("ffi/ur_rtde_shim.cpp")
        .compile("hrc_ur_rtde_shim");

    // The wheel's librtde.so carries its own static Boost, of another version than Debian's
    // headers. The shim's copies of Boost's inline functions (weak, default visibility: Boost
    // marks its error classes visible) would be exported from our binaries, and the dynamic
    // linker would bind librtde's own calls to them: ur_rtde's receive thread then crashed in
    // boost::system::system_error::what on link loss (seen in the link-loss test). So every
    // symbol of the shim except its C entry points is made local.
    let out =
        std::path::PathBuf::from(std::env::var_os("OUT_DIR").expect("OUT_DIR is set by cargo"));
    let archive = out.join("libhrc_ur_rtde_shim.a");
    let status =
        std::process::Command::new(std::env::var("OBJCOPY").unwrap_or_else(|_| "objcopy".into()))
            .arg("--wildcard")
            .arg("--keep-global-symbol=urs_*")
            .arg(&archive)
            .status()
            .unwrap_or_else(|e| {
                panic!("robot-io feature `ur-rtde`: running objcopy (binutils): {e}")
            });
    if !status.success() {
        panic!(
            "robot-io feature `ur-rtde`: objcopy failed on {}",
            archive.display()
        );
    }

    println!("cargo:rustc-link-search=native={}", lib_dir.display());
    println!("cargo:rustc-link-lib=dylib=rtde");
    println!("cargo:rustc-link-lib=dylib=stdc++");
    // Binaries and tests find the library at run time without LD_LIBRARY_PATH.
    println!("cargo:rustc-link-arg=-Wl,-rpath,{}", lib_dir.display());
}
