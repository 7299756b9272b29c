//! Compiles the shared .proto files with pure-Rust tooling (protox): no protoc.
//!
//! Produces the encoded `FileDescriptorSet` (custom options kept) and prost
//! structs that derive `prost_reflect::ReflectMessage`. Every file of
//! `goby/acomms/` is compiled, and a driver's extensions of the driver
//! configuration and of a transmission become fields of them
//! ([`fold_extensions`]): a new driver's `.proto` is the one file it adds.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use prost::Message;
use prost_types::descriptor_proto::ExtensionRange;
use prost_types::{DescriptorProto, FieldDescriptorProto, FileDescriptorProto, FileDescriptorSet};

/// The files compiled besides those of `goby/acomms/` (every one of which
/// is, see [`acomms_files`]).
const FILES: &[&str] = &[
    "dccl/option_extensions.proto",
    "dccl/arithmetic/protobuf/arithmetic.proto",
    "goby/example/navigation.proto",
    "goby/moos/translator.proto",
    "goby/moos/node_report.proto",
    "goby/apps/gobyd_config.proto",
    "goby/sim/scenario.proto",
];

/// Messages a driver's own `.proto` adds its sections to by extending
/// them (inside a message of its own, e.g. in `SeatracConfig`: `extend
/// DriverConfig { optional SeatracConfig seatrac = 2001; }`): the build
/// folds each such extension into the message as a field of its own, so
/// that the driver's settings read and decode as every other driver's
/// (`seatrac { ... }`) and no other file names the driver.
const FOLDED: &[&str] = &[
    ".goby.acomms.protobuf.DriverConfig",
    ".goby.acomms.protobuf.ModemTransmission",
];

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let proto_dir = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR")?).join("proto");
    let out_dir = PathBuf::from(std::env::var("OUT_DIR")?);
    let mut files: Vec<String> = FILES.iter().map(|f| f.to_string()).collect();
    files.extend(acomms_files(&proto_dir)?);
    for file in &files {
        println!("cargo:rerun-if-changed={}", proto_dir.join(file).display());
    }
    // And the files they import (any file under proto/), and a new file
    // in goby/acomms.
    println!("cargo:rerun-if-changed={}", proto_dir.display());
    println!(
        "cargo:rerun-if-changed={}",
        proto_dir.join("goby/acomms").display()
    );

    let mut compiler = protox::Compiler::new([&proto_dir])?;
    compiler.include_imports(true).include_source_info(false);
    compiler.open_files(files.iter())?;
    // The encoded files keep the custom options (DCCL's); prost's
    // descriptor types drop them, so only the files a fold changes are
    // encoded again.
    let encoded = Files::decode(compiler.encode_file_descriptor_set().as_slice())?;
    let mut fds = FileDescriptorSet::default();
    let mut original = BTreeMap::new();
    for bytes in encoded.file {
        let file = FileDescriptorProto::decode(bytes.as_slice())?;
        original.insert(file.name().to_string(), bytes);
        fds.file.push(file);
    }
    let (changed, folded) = fold_extensions(&mut fds)?;
    let files = Files {
        file: fds
            .file
            .iter()
            .map(|f| match changed.contains(f.name()) {
                true => f.encode_to_vec(),
                false => original[f.name()].clone(),
            })
            .collect(),
    };
    std::fs::write(out_dir.join("descriptors.bin"), files.encode_to_vec())?;

    let mut config = prost_build::Config::new();
    for file in &fds.file {
        if file.package() == "google.protobuf" {
            continue;
        }
        let mut names = Vec::new();
        for msg in &file.message_type {
            collect(
                &format!("{}.{}", file.package(), msg.name()),
                msg,
                &mut names,
            );
        }
        for name in names {
            config.type_attribute(
                name.clone(),
                format!(
                    "#[derive(::prost_reflect::ReflectMessage)] \
                     #[prost_reflect(descriptor_pool = \"crate::DESCRIPTOR_POOL\", message_name = \"{name}\")]"
                ),
            );
        }
    }
    // Boxed: a transmission travels through every layer and event, and
    // the Micro-Modem settings (LBL parameters and all) would more than
    // double its size for the few that carry them.
    config.boxed(".goby.acomms.protobuf.ModemTransmission.micromodem");
    // The same for the Popoto's and the Benthos ATM-900's.
    config.boxed(".goby.acomms.protobuf.ModemTransmission.popoto");
    config.boxed(".goby.acomms.protobuf.ModemTransmission.benthos");
    // And every driver's section folded in: the message carrying it stays
    // the size it was for the others.
    for field in &folded {
        config.boxed(field);
    }
    config.out_dir(&out_dir);
    config.compile_fds(fds)?;
    Ok(())
}

/// An encoded `FileDescriptorSet`, each file left encoded.
#[derive(Clone, PartialEq, prost::Message)]
struct Files {
    #[prost(bytes = "vec", repeated, tag = "1")]
    file: Vec<Vec<u8>>,
}

/// Every `.proto` file in `goby/acomms/`, by its import path, in order: a
/// driver's new file is compiled without being listed anywhere.
fn acomms_files(proto_dir: &Path) -> std::io::Result<Vec<String>> {
    let mut files = Vec::new();
    for entry in std::fs::read_dir(proto_dir.join("goby/acomms"))? {
        let name = entry?.file_name().to_string_lossy().into_owned();
        if name.ends_with(".proto") {
            files.push(format!("goby/acomms/{name}"));
        }
    }
    files.sort();
    Ok(files)
}

/// Folds the extensions of the [`FOLDED`] messages declared in
/// `goby/acomms/` into fields of them:
/// the field takes the extension's name and number (carved out of the
/// message's extension ranges), the message's file imports the extending
/// file, and the extending file no longer imports the message's file when
/// it used it only to extend it. The files are then put in the order of
/// their imports. Returns the names of the files changed, none of which
/// may import custom options (they would be lost), and the fields folded
/// in that hold a message (`.package.Message.field`).
fn fold_extensions(fds: &mut FileDescriptorSet) -> Result<(BTreeSet<String>, Vec<String>), String> {
    // Taken out of `extensions`, and of every message's.
    fn take(extensions: &mut Vec<FieldDescriptorProto>) -> Vec<FieldDescriptorProto> {
        let (folded, kept) = std::mem::take(extensions)
            .into_iter()
            .partition(|e| FOLDED.contains(&e.extendee()));
        *extensions = kept;
        folded
    }
    fn take_nested(msg: &mut DescriptorProto, out: &mut Vec<FieldDescriptorProto>) {
        out.extend(take(&mut msg.extension));
        for nested in &mut msg.nested_type {
            take_nested(nested, out);
        }
    }
    let mut moved = Vec::new();
    for (i, file) in fds.file.iter_mut().enumerate() {
        // Only the drivers' own files are folded: another file's extension
        // (Goby 2's `[UDPDriverConfig.local]` read by gobyd's configuration)
        // stays the extension it is declared as.
        if !file.name().starts_with("goby/acomms/") {
            continue;
        }
        let mut folded = take(&mut file.extension);
        for msg in &mut file.message_type {
            take_nested(msg, &mut folded);
        }
        moved.extend(folded.into_iter().map(|e| (i, e)));
    }
    let defined: Vec<BTreeSet<String>> = fds.file.iter().map(defined_types).collect();
    let mut changed = BTreeSet::new();
    let mut folded = Vec::new();
    for (from, mut field) in moved {
        let extendee = field.extendee.take().unwrap_or_default();
        let to = defined
            .iter()
            .position(|d| d.contains(&extendee))
            .ok_or_else(|| format!("{extendee} is in no file compiled"))?;
        let from_name = fds.file[from].name().to_string();
        let to_name = fds.file[to].name().to_string();
        let message = top_message(&mut fds.file[to], &extendee)
            .ok_or_else(|| format!("{extendee} is not a message of {to_name}"))?;
        if let Some(clash) = message
            .field
            .iter()
            .find(|f| f.number == field.number || f.name == field.name)
        {
            return Err(format!(
                "{from_name}: extension {} = {} of {extendee} clashes with its field {} = {}",
                field.name(),
                field.number(),
                clash.name(),
                clash.number()
            ));
        }
        carve(&mut message.extension_range, field.number());
        if field.r#type() == prost_types::field_descriptor_proto::Type::Message {
            folded.push(format!("{extendee}.{}", field.name()));
        }
        message.field.push(field);
        changed.insert(from_name.clone());
        changed.insert(to_name.clone());
        if from != to && !fds.file[to].dependency.contains(&from_name) {
            fds.file[to].dependency.push(from_name.clone());
        }
        let uses_target = referenced_types(&fds.file[from])
            .iter()
            .any(|t| defined[to].contains(t));
        if !uses_target {
            let file = &mut fds.file[from];
            if !file.public_dependency.is_empty() || !file.weak_dependency.is_empty() {
                return Err(format!(
                    "{from_name}: public or weak imports are not folded"
                ));
            }
            file.dependency.retain(|d| *d != to_name);
        }
    }
    // Files defining custom options (extending google.protobuf's).
    let options: BTreeSet<&str> = fds
        .file
        .iter()
        .filter(|f| {
            f.extension
                .iter()
                .any(|e| e.extendee().starts_with(".google.protobuf."))
        })
        .map(|f| f.name())
        .collect();
    for file in fds.file.iter().filter(|f| changed.contains(f.name())) {
        if let Some(o) = file
            .dependency
            .iter()
            .find(|d| options.contains(d.as_str()))
        {
            return Err(format!(
                "{}: extends {} and imports custom options ({o}), which folding would lose",
                file.name(),
                FOLDED.join(" or ")
            ));
        }
    }
    sort_by_imports(fds)?;
    Ok((changed, folded))
}

/// Removes `number` from the extension ranges (start inclusive, end
/// exclusive).
fn carve(ranges: &mut Vec<ExtensionRange>, number: i32) {
    let mut out = Vec::new();
    for r in ranges.drain(..) {
        let (start, end) = (r.start(), r.end());
        if !(start..end).contains(&number) {
            out.push(r);
            continue;
        }
        if start < number {
            out.push(ExtensionRange {
                end: Some(number),
                ..r.clone()
            });
        }
        if number + 1 < end {
            out.push(ExtensionRange {
                start: Some(number + 1),
                ..r
            });
        }
    }
    *ranges = out;
}

/// The top-level message of `file` named `full` (`.package.Name`).
fn top_message<'a>(
    file: &'a mut FileDescriptorProto,
    full: &str,
) -> Option<&'a mut DescriptorProto> {
    let prefix = format!(".{}.", file.package());
    let name = full.strip_prefix(&prefix)?;
    file.message_type.iter_mut().find(|m| m.name() == name)
}

/// The full names (`.package.Name.Nested`) of the messages and enums `file`
/// defines.
fn defined_types(file: &FileDescriptorProto) -> BTreeSet<String> {
    fn walk(prefix: &str, msg: &DescriptorProto, out: &mut BTreeSet<String>) {
        let name = format!("{prefix}.{}", msg.name());
        for e in &msg.enum_type {
            out.insert(format!("{name}.{}", e.name()));
        }
        for nested in &msg.nested_type {
            walk(&name, nested, out);
        }
        out.insert(name);
    }
    let prefix = format!(".{}", file.package());
    let mut out = BTreeSet::new();
    for e in &file.enum_type {
        out.insert(format!("{prefix}.{}", e.name()));
    }
    for msg in &file.message_type {
        walk(&prefix, msg, &mut out);
    }
    out
}

/// The types `file`'s fields and extensions name (and extend).
fn referenced_types(file: &FileDescriptorProto) -> BTreeSet<String> {
    fn walk(msg: &DescriptorProto, out: &mut BTreeSet<String>) {
        for f in msg.field.iter().chain(&msg.extension) {
            out.extend(f.type_name.clone());
            out.extend(f.extendee.clone());
        }
        for nested in &msg.nested_type {
            walk(nested, out);
        }
    }
    let mut out = BTreeSet::new();
    for f in &file.extension {
        out.extend(f.type_name.clone());
        out.extend(f.extendee.clone());
    }
    for msg in &file.message_type {
        walk(msg, &mut out);
    }
    out
}

/// Puts every file after the files it imports; an import circle is an
/// error.
fn sort_by_imports(fds: &mut FileDescriptorSet) -> Result<(), String> {
    let mut files: BTreeMap<String, FileDescriptorProto> = fds
        .file
        .drain(..)
        .map(|f| (f.name().to_string(), f))
        .collect();
    let names: Vec<String> = files.keys().cloned().collect();
    let mut done = BTreeSet::new();
    let mut order = Vec::new();
    fn visit(
        name: &str,
        files: &BTreeMap<String, FileDescriptorProto>,
        path: &mut Vec<String>,
        done: &mut BTreeSet<String>,
        order: &mut Vec<String>,
    ) -> Result<(), String> {
        if done.contains(name) {
            return Ok(());
        }
        if path.iter().any(|p| p == name) {
            return Err(format!("import circle: {} -> {name}", path.join(" -> ")));
        }
        path.push(name.to_string());
        for dep in files
            .get(name)
            .map(|f| f.dependency.clone())
            .unwrap_or_default()
        {
            visit(&dep, files, path, done, order)?;
        }
        path.pop();
        done.insert(name.to_string());
        order.push(name.to_string());
        Ok(())
    }
    for name in &names {
        visit(name, &files, &mut Vec::new(), &mut done, &mut order)?;
    }
    fds.file = order.iter().filter_map(|n| files.remove(n)).collect();
    Ok(())
}

fn collect(name: &str, msg: &prost_types::DescriptorProto, out: &mut Vec<String>) {
    out.push(name.to_string());
    for nested in &msg.nested_type {
        if nested
            .options
            .as_ref()
            .and_then(|o| o.map_entry)
            .unwrap_or(false)
        {
            continue;
        }
        collect(&format!("{name}.{}", nested.name()), nested, out);
    }
}
