//! Compiling `.proto` files at run time with pure-Rust tooling (protox).
//!
//! `dccl/option_extensions.proto` and the codec option files
//! (`dccl/arithmetic/protobuf/arithmetic_extensions.proto`,
//! `dccl/arithmetic/protobuf/arithmetic.proto`, `goby/dccl/delta_extensions.proto`)
//! are embedded: a file that imports them needs no include path for them and
//! no copy on disk. The older path of the options,
//! `dccl/protobuf/option_extensions.proto`, resolves to the same options.

use std::path::{Path, PathBuf};

use miette::Diagnostic;
use prost_reflect::DescriptorPool;
use protox::file::{
    ChainFileResolver, File, FileResolver, GoogleFileResolver, IncludeFileResolver,
};

use crate::error::{Error, Result};

/// The import path of the DCCL options used by older message sets; libdccl
/// 4 still ships it as a file that publicly imports the current one.
pub const LEGACY_OPTION_EXTENSIONS_PATH: &str = "dccl/protobuf/option_extensions.proto";

/// Serves the embedded DCCL option extensions and codec option files.
struct EmbeddedResolver;

impl FileResolver for EmbeddedResolver {
    fn open_file(&self, name: &str) -> std::result::Result<File, protox::Error> {
        if name == LEGACY_OPTION_EXTENSIONS_PATH {
            let source = format!(
                "syntax = \"proto2\";\nimport public \"{}\";\n",
                protos::OPTION_EXTENSIONS_PATH
            );
            return File::from_source(name, &source);
        }
        match protos::DCCL_EMBEDDED_PROTOS
            .iter()
            .find(|(path, _)| *path == name)
        {
            Some((path, source)) => File::from_source(path, source),
            None => Err(protox::Error::file_not_found(name)),
        }
    }
}

/// An include directory whose files are checked for runaway nesting
/// ([`crate::nesting`]) before the parser sees them.
struct GuardedInclude {
    dir: PathBuf,
    inner: IncludeFileResolver,
}

impl GuardedInclude {
    fn new(dir: PathBuf) -> Self {
        GuardedInclude {
            inner: IncludeFileResolver::new(dir.clone()),
            dir,
        }
    }
}

impl FileResolver for GuardedInclude {
    fn resolve_path(&self, path: &Path) -> Option<String> {
        self.inner.resolve_path(path)
    }

    fn open_file(&self, name: &str) -> std::result::Result<File, protox::Error> {
        let path = self.dir.join(name);
        if let Ok(source) = std::fs::read_to_string(&path) {
            crate::nesting::check(&path.display().to_string(), &source)
                .map_err(protox::Error::new)?;
        }
        self.inner.open_file(name)
    }
}

fn absolute(path: &Path) -> PathBuf {
    std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf())
}

/// Compiles `.proto` files into a descriptor pool (custom options preserved).
///
/// Imports are searched in `include_dirs`, then in the directory of each
/// file, then among the embedded files (`dccl/option_extensions.proto`, the
/// codec option files and the `google/protobuf/*.proto` well-known types).
pub fn compile_protos(
    files: &[impl AsRef<Path>],
    include_dirs: &[impl AsRef<Path>],
) -> Result<DescriptorPool> {
    let mut dirs: Vec<PathBuf> = include_dirs.iter().map(|d| absolute(d.as_ref())).collect();
    let mut paths = Vec::with_capacity(files.len());
    for file in files {
        let file = file.as_ref();
        if !file.is_file() {
            return Err(Error::Proto(format!("{}: no such file", file.display())));
        }
        let path = absolute(file);
        if let Some(parent) = path.parent() {
            if !dirs.iter().any(|d| d == parent) {
                dirs.push(parent.to_path_buf());
            }
        }
        paths.push(path);
    }
    on_large_stack(move || {
        let mut resolver = ChainFileResolver::new();
        for dir in &dirs {
            resolver.add(GuardedInclude::new(dir.clone()));
        }
        resolver.add(EmbeddedResolver);
        resolver.add(GoogleFileResolver::new());
        let mut compiler = protox::Compiler::with_file_resolver(resolver);
        compiler.include_imports(true).include_source_info(false);
        for path in &paths {
            compiler.open_file(path).map_err(|e| {
                let mut text =
                    describe(&e, &path.display().to_string(), |name| on_disk(&dirs, name));
                // An import no include directory holds: say where it was
                // looked for (the tools' -I adds a directory).
                if e.is_file_not_found() && text.contains("import") {
                    let looked: Vec<String> =
                        dirs.iter().map(|d| d.display().to_string()).collect();
                    text.push_str(&format!(
                        " (looked in {} and the embedded DCCL and google/protobuf files; \
                         add the directory that holds it to the include paths, -I DIR)",
                        looked.join(", ")
                    ));
                }
                Error::Proto(text)
            })?;
        }
        decode_pool(&compiler.encode_file_descriptor_set())
    })
}

/// Name given by the compiler to `file`: its path relative to the first
/// include directory that holds it (the `-I` directories, then its own), or
/// failing that the longest file name of the pool that ends `file`'s path.
/// `None` when the pool holds no such file.
pub fn pool_file_name(pool: &DescriptorPool, file: &Path, include: &[PathBuf]) -> Option<String> {
    let path = std::fs::canonicalize(file).ok()?;
    let mut dirs: Vec<PathBuf> = include
        .iter()
        .filter_map(|d| std::fs::canonicalize(d).ok())
        .collect();
    if let Some(parent) = path.parent() {
        dirs.push(parent.to_path_buf());
    }
    for dir in &dirs {
        if let Ok(rel) = path.strip_prefix(dir) {
            let name = rel
                .components()
                .map(|c| c.as_os_str().to_string_lossy().into_owned())
                .collect::<Vec<_>>()
                .join("/");
            if pool.get_file_by_name(&name).is_some() {
                return Some(name);
            }
        }
    }
    pool.files()
        .filter(|f| path.ends_with(f.name()))
        .max_by_key(|f| f.name().len())
        .map(|f| f.name().to_string())
}

/// Compiles `.proto` sources held in memory: `(file name, source text)` pairs,
/// which may import each other by those names.
pub fn compile_sources(sources: &[(&str, &str)]) -> Result<DescriptorPool> {
    struct Memory(Vec<(String, String)>);
    impl FileResolver for Memory {
        fn open_file(&self, name: &str) -> std::result::Result<File, protox::Error> {
            match self.0.iter().find(|(n, _)| n == name) {
                Some((n, s)) => {
                    crate::nesting::check(n, s).map_err(protox::Error::new)?;
                    File::from_source(n, s)
                }
                None => Err(protox::Error::file_not_found(name)),
            }
        }
    }
    let memory = Memory(
        sources
            .iter()
            .map(|(n, s)| (n.to_string(), s.to_string()))
            .collect(),
    );
    let names: Vec<String> = sources.iter().map(|(n, _)| n.to_string()).collect();
    on_large_stack(move || {
        let mut resolver = ChainFileResolver::new();
        resolver.add(memory);
        resolver.add(EmbeddedResolver);
        resolver.add(GoogleFileResolver::new());
        let mut compiler = protox::Compiler::with_file_resolver(resolver);
        compiler.include_imports(true).include_source_info(false);
        for name in &names {
            compiler
                .open_file(name)
                .map_err(|e| Error::Proto(describe(&e, name, str::to_string)))?;
        }
        decode_pool(&compiler.encode_file_descriptor_set())
    })
}

/// The text of a compiler error: `file:LINE:COLUMN: message` (1-based; the
/// column counts bytes, as protoc's does) when the error has a place in a
/// file, `file: message` when it names a file only. The file is the one the
/// fault is in, which may be an imported one; `shown` turns the compiler's
/// name for it into the name given to the user. `opened` (the file being
/// compiled) is named when the error names no file. The causes the
/// compiler gives (such as the unknown key inside an option value) follow
/// the message.
fn describe(err: &protox::Error, opened: &str, shown: impl Fn(&str) -> String) -> String {
    let file = match err.file() {
        Some(name) => shown(name),
        None => opened.to_string(),
    };
    let mut message = err.to_string();
    let mut cause = err.diagnostic_source();
    while let Some(inner) = cause {
        message = format!("{message}: {inner}");
        cause = inner.diagnostic_source();
    }
    match place(err) {
        Some((line, column)) => format!("{file}:{line}:{column}: {message}"),
        None => format!("{file}: {message}"),
    }
}

/// Line and column (1-based) of the fault `err` reports. The compiler's own
/// `name:LINE:COLUMN: message` rendering (its `Debug` form) places the error
/// at its primary span; failing that, the first labelled span is used.
fn place(err: &protox::Error) -> Option<(usize, usize)> {
    let rendered = format!("{err:?}");
    let from_rendering = err.file().and_then(|name| {
        let middle = rendered
            .strip_prefix(name)?
            .strip_prefix(':')?
            .strip_suffix(&err.to_string())?;
        let (line, column) = middle.strip_suffix(": ")?.split_once(':')?;
        Some((line.parse().ok()?, column.parse().ok()?))
    });
    from_rendering.or_else(|| {
        let source = err.source_code()?;
        let label = err.labels()?.next()?;
        let contents = source.read_span(label.inner(), 0, 0).ok()?;
        Some((contents.line() + 1, contents.column() + 1))
    })
}

/// The path of the file the compiler calls `name`: in the first of `dirs`
/// that holds it, or `name` itself for an embedded file.
fn on_disk(dirs: &[PathBuf], name: &str) -> String {
    dirs.iter()
        .map(|dir| dir.join(name))
        .find(|path| path.is_file())
        .map_or_else(|| name.to_string(), |path| path.display().to_string())
}

/// Stack of the thread that parses `.proto` files: the parser recurses once
/// per nested option value (about 20 KiB a level in a debug build), so the
/// [`MAX_NESTING`](crate::nesting::MAX_NESTING) levels the nesting guard
/// lets through must not depend on the caller's stack (2 MiB on a spawned
/// thread). Reserved address space, not memory in use.
const COMPILER_STACK_BYTES: usize = 64 << 20;

/// Runs the compilation `f` on a thread with [`COMPILER_STACK_BYTES`] of stack.
fn on_large_stack(f: impl FnOnce() -> Result<DescriptorPool> + Send) -> Result<DescriptorPool> {
    std::thread::scope(|scope| {
        let handle = std::thread::Builder::new()
            .name("proto-compiler".into())
            .stack_size(COMPILER_STACK_BYTES)
            .spawn_scoped(scope, f)
            .map_err(|e| Error::Proto(format!("cannot start the .proto compiler thread: {e}")))?;
        handle
            .join()
            .unwrap_or_else(|panic| std::panic::resume_unwind(panic))
    })
}

fn decode_pool(bytes: &[u8]) -> Result<DescriptorPool> {
    DescriptorPool::decode(bytes).map_err(|e| Error::Proto(e.to_string()))
}
