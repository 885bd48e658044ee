//! Every push-constant block in the SPIR-V matches its `#[repr(C)]` Rust mirror, member by
//! member (name, offset) and in size; every shader's interface is sane.

use dispflow_vk::{kernels, shaders};

#[test]
fn push_constants_match_rust_structs() {
    let rust = kernels::param_layouts();
    let mut checked = 0;
    for sh in shaders::ALL {
        if sh.push_constant_size == 0 {
            continue;
        }
        let (name, size, fields) = rust
            .iter()
            .find(|r| r.0 == sh.push_constant_struct)
            .unwrap_or_else(|| {
                panic!(
                    "{}: no Rust mirror for push-constant struct {:?}",
                    sh.name, sh.push_constant_struct
                )
            });
        assert_eq!(
            *size as u32, sh.push_constant_size,
            "{}: size of {name}",
            sh.name
        );
        assert_eq!(
            fields.len(),
            sh.push_constant_members.len(),
            "{}: member count of {name}",
            sh.name
        );
        for ((rf, ro), (gf, go)) in fields.iter().zip(sh.push_constant_members) {
            assert_eq!(rf, gf, "{}: member order/name in {name}", sh.name);
            assert_eq!(*ro as u32, *go, "{}: offset of {name}.{rf}", sh.name);
        }
        checked += 1;
    }
    assert!(
        checked >= 8,
        "only {checked} shaders with push constants were checked"
    );
}

#[test]
fn shader_table_is_complete_and_sane() {
    let names: Vec<&str> = shaders::ALL.iter().map(|s| s.name).collect();
    for want in [
        "scan/scan_setup",
        "scan/scan_reduce",
        "scan/scan_top",
        "scan/scan_down",
        "sort/radix_hist_u32",
        "sort/radix_scatter_u64",
    ] {
        assert!(
            names.contains(&want),
            "{want} missing from the shader table: {names:?}"
        );
    }
    let mut sorted = names.clone();
    sorted.sort();
    assert_eq!(
        names, sorted,
        "table order is deterministic (sorted by path)"
    );
    for sh in shaders::ALL {
        assert_eq!(
            &sh.spirv[..4],
            &0x0723_0203u32.to_le_bytes(),
            "{}: SPIR-V magic",
            sh.name
        );
        let inv: u32 = sh.workgroup_size.iter().product();
        assert!(
            (1..=1024).contains(&inv),
            "{}: workgroup {:?}",
            sh.name,
            sh.workgroup_size
        );
        for (i, b) in sh.bindings.iter().enumerate() {
            assert_eq!(
                b.binding, i as u32,
                "{}: bindings are dense and ordered",
                sh.name
            );
            assert!(
                !(b.readonly && b.writeonly),
                "{}: binding {}",
                sh.name,
                b.binding
            );
        }
        assert!(
            sh.push_constant_size <= 128,
            "{}: lavapipe allows 128 bytes of push constants",
            sh.name
        );
    }
}
