//! The process-wide descriptor pool behind `dccl.loadProtoFile` and
//! `dccl.addProtoIncludePath`, as the reference binding keeps one in its
//! dynamic protobuf manager.
//!
//! Files enter it three ways: compiled from `.proto` text at run time (no
//! `protoc`), as serialized `FileDescriptorProto`s taken from a generated
//! `_pb2` module (`DESCRIPTOR.serialized_pb`, custom options kept), and the
//! embedded DCCL option files, which are always there.

use std::path::PathBuf;
use std::sync::{LazyLock, Mutex, MutexGuard};

use dccl::prost_reflect::prost_types::{DescriptorProto, FileDescriptorProto};
use dccl::prost_reflect::{DescriptorPool, EnumDescriptor, FileDescriptor, MessageDescriptor};
use prost::Message;

/// Import paths of the embedded option files, as user files import them.
pub const EMBEDDED_FILES: [&str; 4] = [
    protos::OPTION_EXTENSIONS_PATH,
    protos::ARITHMETIC_PATH,
    protos::ARITHMETIC_EXTENSIONS_PATH,
    protos::DELTA_EXTENSIONS_PATH,
];

struct State {
    pool: DescriptorPool,
    include_dirs: Vec<PathBuf>,
}

static STATE: LazyLock<Mutex<State>> = LazyLock::new(|| {
    Mutex::new(State {
        pool: embedded_pool(),
        include_dirs: Vec::new(),
    })
});

/// The embedded option files (and `google/protobuf/descriptor.proto`),
/// compiled once from the sources the `protos` crate carries.
fn embedded_pool() -> DescriptorPool {
    let importer: String = EMBEDDED_FILES
        .iter()
        .map(|f| format!("import \"{f}\";\n"))
        .collect();
    let source = format!("syntax = \"proto2\";\n{importer}");
    let compiled = dccl::compile_sources(&[("dccl-python-embedded.proto", &source)])
        .expect("the embedded DCCL option files compile");
    let mut pool = DescriptorPool::new();
    for file in compiled.files() {
        if file.name() != "dccl-python-embedded.proto" {
            pool.decode_file_descriptor_proto(file.encode_to_vec().as_slice())
                .expect("the embedded DCCL option files form a pool");
        }
    }
    pool
}

fn state() -> MutexGuard<'static, State> {
    // A panic while the lock is held cannot leave the pool half-built (every
    // change is a whole-file add), so a poisoned lock is still usable.
    STATE.lock().unwrap_or_else(|e| e.into_inner())
}

/// Adds a directory searched for `import`s of files loaded later.
/// Errors when `dir` is not a directory.
pub fn add_include_path(dir: PathBuf) -> dccl::Result<()> {
    if !dir.is_dir() {
        return Err(dccl::Error::Proto(format!(
            "{}: no such directory (include path)",
            dir.display()
        )));
    }
    let mut s = state();
    if !s.include_dirs.contains(&dir) {
        s.include_dirs.push(dir);
    }
    Ok(())
}

/// Compiles a `.proto` file (and its imports) into the pool; returns the
/// full names of the message types the file itself defines, nested ones
/// included. A type has one definition in the pool: loading a file again,
/// or another file defining the same types the same way, adds nothing; a
/// file defining an already loaded type differently is refused (the error
/// names the type) and the pool is left as it was.
pub fn load_proto_file(path: PathBuf) -> dccl::Result<Vec<String>> {
    let dirs = state().include_dirs.clone();
    let compiled = dccl::compile_protos(&[&path], &dirs)?;
    let mut s = state();
    // The file asked for is the last one of the compiled set (imports come first).
    let mut names = Vec::new();
    let files: Vec<FileDescriptor> = compiled.files().collect();
    for file in &files {
        if let Some(clash) = clash(&s.pool, file) {
            return Err(dccl::Error::Proto(format!("{}: {clash}", path.display())));
        }
    }
    for file in &files {
        merge(&mut s.pool, file)?;
    }
    if let Some(file) = files.last() {
        let mut stack: Vec<MessageDescriptor> = file.messages().collect();
        while let Some(m) = stack.pop() {
            stack.extend(m.child_messages());
            names.push(m.full_name().to_string());
        }
    }
    names.sort();
    Ok(names)
}

/// Adds one file from its serialized `FileDescriptorProto` (custom options
/// kept). A file whose name, or one of whose top-level types, is already in
/// the pool is left out, so a generated module of a file loaded from its
/// `.proto` adds nothing and the loaded definitions stay.
/// Returns whether the file was added.
pub fn add_serialized_file(bytes: &[u8]) -> dccl::Result<bool> {
    let proto = FileDescriptorProto::decode(bytes)
        .map_err(|e| dccl::Error::Proto(format!("not a serialized FileDescriptorProto: {e}")))?;
    let name = proto.name().to_string();
    let mut s = state();
    if s.pool.get_file_by_name(&name).is_some() {
        return Ok(false);
    }
    if defined_elsewhere(&s.pool, &proto) {
        return Ok(false);
    }
    s.pool
        .decode_file_descriptor_proto(bytes)
        .map_err(|e| dccl::Error::Proto(format!("{name}: {e}")))?;
    Ok(true)
}

/// Whether a top-level message or enum of `file` is already in the pool:
/// the same definitions entered under another file name (a `.proto`
/// compiled from one include directory, its generated module from another).
/// Those already there stay.
fn defined_elsewhere(pool: &DescriptorPool, file: &FileDescriptorProto) -> bool {
    let full = |n: &str| {
        if file.package().is_empty() {
            n.to_string()
        } else {
            format!("{}.{n}", file.package())
        }
    };
    file.message_type
        .iter()
        .any(|m| pool.get_message_by_name(&full(m.name())).is_some())
        || file
            .enum_type
            .iter()
            .any(|e| pool.get_enum_by_name(&full(e.name())).is_some())
}

/// How `file` contradicts the pool: a message or enum type the pool holds
/// with another definition (the innermost differing type is named), or a
/// file of the same name that lacks one of `file`'s types. `None` when every
/// type of `file` already there is defined the same way.
fn clash(pool: &DescriptorPool, file: &FileDescriptor) -> Option<String> {
    let differing = file
        .messages()
        .find_map(|m| differing_message(pool, &m))
        .or_else(|| file.enums().find_map(|e| differing_enum(pool, &e)));
    if let Some((name, old_file)) = differing {
        return Some(format!(
            "type {name} is already loaded with another definition (from {old_file}); \
             a type has one definition per process"
        ));
    }
    pool.get_file_by_name(file.name())?;
    let mut stack: Vec<MessageDescriptor> = file.messages().collect();
    while let Some(m) = stack.pop() {
        if pool.get_message_by_name(m.full_name()).is_none() {
            return Some(format!(
                "file {} is already loaded, without type {}",
                file.name(),
                m.full_name()
            ));
        }
        stack.extend(m.child_messages());
    }
    None
}

/// `(full name, file of the pool's definition)` of `new` or of the innermost
/// type nested in it that the pool defines differently.
fn differing_message(pool: &DescriptorPool, new: &MessageDescriptor) -> Option<(String, String)> {
    let old = pool.get_message_by_name(new.full_name())?;
    if message_definition(&old) == message_definition(new) {
        return None;
    }
    new.child_messages()
        .find_map(|m| differing_message(pool, &m))
        .or_else(|| new.child_enums().find_map(|e| differing_enum(pool, &e)))
        .or_else(|| {
            Some((
                new.full_name().to_string(),
                old.parent_file().name().to_string(),
            ))
        })
}

fn differing_enum(pool: &DescriptorPool, new: &EnumDescriptor) -> Option<(String, String)> {
    let old = pool.get_enum_by_name(new.full_name())?;
    (enum_definition(&old) != enum_definition(new)).then(|| {
        (
            new.full_name().to_string(),
            old.parent_file().name().to_string(),
        )
    })
}

/// A message type's definition as comparable bytes: its descriptor
/// without the derived JSON names (which some compilers record and others
/// leave out) and the options (custom ones, such as `(dccl.field)`,
/// included) of the message, its fields and oneofs, then the same of each
/// nested type.
fn message_definition(m: &MessageDescriptor) -> Vec<Vec<u8>> {
    let mut proto: DescriptorProto = m.descriptor_proto().clone();
    for field in proto.field.iter_mut().chain(proto.extension.iter_mut()) {
        field.json_name = None;
    }
    proto.nested_type.clear();
    proto.enum_type.clear();
    let mut out = vec![proto.encode_to_vec(), m.options().encode_to_vec()];
    out.extend(m.fields().map(|f| f.options().encode_to_vec()));
    out.extend(m.oneofs().map(|o| o.options().encode_to_vec()));
    for child in m.child_messages() {
        out.extend(message_definition(&child));
    }
    for child in m.child_enums() {
        out.extend(enum_definition(&child));
    }
    out
}

/// An enum type's definition as comparable bytes: its descriptor and the
/// options of the enum and of its values.
fn enum_definition(e: &EnumDescriptor) -> Vec<Vec<u8>> {
    let mut out = vec![
        e.enum_descriptor_proto().encode_to_vec(),
        e.options().encode_to_vec(),
    ];
    out.extend(e.values().map(|v| v.options().encode_to_vec()));
    out
}

fn merge(pool: &mut DescriptorPool, file: &FileDescriptor) -> dccl::Result<()> {
    if pool.get_file_by_name(file.name()).is_some()
        || defined_elsewhere(pool, file.file_descriptor_proto())
    {
        return Ok(());
    }
    pool.decode_file_descriptor_proto(file.encode_to_vec().as_slice())
        .map_err(|e| dccl::Error::Proto(format!("{}: {e}", file.name())))
}

/// Whether a file of that name is in the pool.
pub fn has_file(name: &str) -> bool {
    state().pool.get_file_by_name(name).is_some()
}

/// A message type of the pool by full name.
pub fn message(full_name: &str) -> Option<MessageDescriptor> {
    state().pool.get_message_by_name(full_name)
}

/// Serialized `FileDescriptorProto` of the file `name`, custom options kept.
pub fn file_bytes(name: &str) -> Option<Vec<u8>> {
    state()
        .pool
        .get_file_by_name(name)
        .map(|f| f.encode_to_vec())
}

/// Serialized `FileDescriptorProto`s of the file defining `desc` and of
/// every file it imports, imports first: the order a Python descriptor pool
/// accepts them in.
pub fn files_for(desc: &MessageDescriptor) -> Vec<(String, Vec<u8>)> {
    fn visit(file: FileDescriptor, seen: &mut Vec<String>, out: &mut Vec<(String, Vec<u8>)>) {
        if seen.iter().any(|n| n == file.name()) {
            return;
        }
        seen.push(file.name().to_string());
        for dep in file.dependencies() {
            visit(dep, seen, out);
        }
        out.push((file.name().to_string(), file.encode_to_vec()));
    }
    let mut out = Vec::new();
    visit(desc.parent_file(), &mut Vec::new(), &mut out);
    out
}
