//! `goby dccl wireshark`: writes a Wireshark dissector (Lua) for the DCCL
//! messages of the user's `.proto` files, which decodes them, header and
//! fields, found by their DCCL id, inside the UDP driver's datagrams (each
//! a protobuf `goby.acomms.protobuf.ModemTransmission`, whose `frame`s hold
//! DCCL messages back to back, then zero padding, and whose
//! `frame_identity` entries hold gobyd's `FrameIdentity` of each frame's
//! messages) and inside captures of raw frames (one frame a packet, on a
//! `USER` link type; a frame a modem carried ends with gobyd's trailer).
//!
//! The dissector is a schema written from the loaded types (each field's
//! codec and its parameters, as DCCL's default codecs derive them from the
//! `(dccl.field)` options: the module `schema`) followed by a fixed decoder
//! (`dissector.lua`) implementing DCCL's bit-packed decoding: the default
//! numeric codec with bounds and precision or resolution, bools, enums
//! (packed or not), strings and bytes (versions 2 and 3 with their length
//! prefix or fixed size, version 4's variable length), embedded messages
//! (presence bits from version 3), repeated fields (the count prefix from
//! version 3), version 4's oneofs, and the time, static, presence,
//! var_bytes and id codecs. Dynamic conditions (`omit_if`, `required_if`,
//! `only_if`, `min`, `max`; the module `conditions`) run in Wireshark's Lua
//! on the message decoded so far, as the codec evaluates them. Each
//! message shows as `goby dccl decode` prints it. A type using another
//! codec (hash, arithmetic, delta, a codec of the user's), an `omit_id`
//! type (it cannot be found by id), a 64-bit field of more than 52 bits
//! with a resolution other than 1 or with dynamic bounds, or dynamic
//! conditions on a field of a codec other than the default, time and
//! var_bytes ones is refused: named on standard error with the field and
//! the reason, and shown in Wireshark as "not dissected" with that reason.
//! Encrypted bodies are not decrypted.

mod conditions;
mod schema;

use std::io::Write;
use std::path::PathBuf;

use clap::Args;
use prost_reflect::ReflectMessage;

use crate::dccl_cmd::{Definitions, ProtoArgs};
use crate::{CliError, Status};

/// The decoder that follows the schema in the dissector written.
const DECODER: &str = include_str!("dissector.lua");

/// Arguments of `goby dccl wireshark`.
#[derive(Debug, Args)]
#[command(
    long_about = "Write a Wireshark dissector (Lua) for the DCCL messages of the .proto files: \
    each message, found by its DCCL id, decoded field by field inside the UDP driver's datagrams \
    (Goby's and gobyd's ModemTransmission) and inside captures of raw frames (--user-dlt). Types \
    it cannot decode are named on standard error, with why.\n\n\
    Examples:\n  \
    goby dccl wireshark -f my_messages.proto --udp-port 50001 --udp-port 50002 -o ~/.local/lib/wireshark/plugins/dccl.lua\n  \
    tshark -X lua_script:dccl.lua -r capture.pcap -Y dccl -T fields -e dccl.message"
)]
pub struct WiresharkArgs {
    /// Message definitions: every valid DCCL message of the files.
    #[command(flatten)]
    pub proto: ProtoArgs,
    /// A UDP port of the UDP driver (each node's `udp.local` port) whose
    /// datagrams are dissected (may be repeated; others by Wireshark's
    /// "Decode As...": goby_udp).
    #[arg(long = "udp-port", value_name = "PORT")]
    pub udp_port: Vec<u16>,
    /// Dissect packets of link type USER N (0-15; DLT 147 + N) as raw DCCL
    /// frames, one frame a packet.
    #[arg(long = "user-dlt", value_name = "N", value_parser = clap::value_parser!(u8).range(0..=15))]
    pub user_dlt: Option<u8>,
    /// Write the dissector to this file (default: standard output).
    #[arg(short = 'o', long = "output", value_name = "FILE.lua")]
    pub output: Option<PathBuf>,
}

/// Runs `goby dccl wireshark`.
pub fn run(
    args: &WiresharkArgs,
    stdout: &mut dyn Write,
    stderr: &mut dyn Write,
) -> Result<Status, CliError> {
    let defs = Definitions::compile(&args.proto)?;
    let mut codec = defs.new_codec(None, false)?;
    let names = defs.load_valid(&mut codec, stderr)?;
    let mut types = Vec::new();
    for name in &names {
        types.push(defs.message(name)?);
    }
    // gobyd's frame trailer, unless one of the user's types has its id.
    let trailer = protos::goby::acomms::protobuf::FrameIdentity::default().descriptor();
    let trailer_id = queue::identity::DCCL_ID;
    if names
        .iter()
        .all(|n| codec.id_of(n).ok() != Some(trailer_id))
    {
        codec
            .load(&trailer)
            .map_err(|e| CliError::setup(format!("cannot load the frame trailer: {e}")))?;
        types.push(trailer);
    }
    let written = schema::write(&codec, &types, &args.udp_port, args.user_dlt);
    for refusal in &written.refused {
        writeln!(stderr, "goby: warning: not dissected: {refusal}")?;
    }
    let text = format!("{}\n{DECODER}", written.lua);
    match &args.output {
        None => stdout.write_all(text.as_bytes())?,
        Some(path) => std::fs::write(path, text)
            .map_err(|e| CliError::setup(format!("cannot write {}: {e}", path.display())))?,
    }
    Ok(Status::Ok)
}
