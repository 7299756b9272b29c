//! The evaluator against the Lua 5.3 interpreter (`lua5.3`, Debian's
//! package of that name), when one is on the `PATH`: seeded random
//! expressions over numbers (integers, floats, the edges of both), strings
//! (numeric and not), booleans and nil, with every operator and the library
//! functions supported, each evaluated by both; the type and `tostring` of
//! the value, or an error, must agree. Without `lua5.3` the test says it is
//! skipped.

use std::io::Write;
use std::process::{Command, Stdio};

use super::eval::{run, Env, Val};
use super::parser::parse_script;
use super::view::Node;

/// A tiny deterministic generator (no dependency on a crate's RNG here).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    fn pick<'a>(&mut self, items: &[&'a str]) -> &'a str {
        items[(self.next() % items.len() as u64) as usize]
    }
}

const ATOMS: &[&str] = &[
    "0",
    "1",
    "2",
    "3",
    "-1",
    "7",
    "10",
    "255",
    "9007199254740993",
    "9223372036854775807",
    "-9223372036854775807",
    "0x10",
    "0xff",
    "0.5",
    "-0.0",
    "2.5",
    "1e15",
    "1e300",
    "3.0",
    "0.1",
    "1/0",
    "-1/0",
    "'10'",
    "'2.5'",
    "' 7 '",
    "'0x1A'",
    "'abc'",
    "''",
    "'9'",
    "true",
    "false",
    "nil",
    "math.huge",
    "math.pi",
    "math.maxinteger",
    "math.mininteger",
];

const BINARY: &[&str] = &[
    "+", "-", "*", "/", "//", "%", "^", "..", "==", "~=", "<", "<=", ">", ">=", "and", "or", "&",
    "|", "~", "<<", ">>",
];

const CALLS: &[&str] = &[
    "math.floor",
    "math.ceil",
    "math.abs",
    "math.sqrt",
    "math.tointeger",
    "math.type",
    "tostring",
    "tonumber",
    "type",
    "string.len",
    "string.upper",
];

fn expression(rng: &mut Rng, depth: u32) -> String {
    if depth == 0 || rng.next().is_multiple_of(3) {
        return rng.pick(ATOMS).to_string();
    }
    match rng.next() % 8 {
        0 => format!("(- {})", expression(rng, depth - 1)),
        1 => format!("(not {})", expression(rng, depth - 1)),
        2 => format!("#{}", rng.pick(&["'abc'", "''", "'12345'"])),
        3 => format!("{}({})", rng.pick(CALLS), expression(rng, depth - 1)),
        4 => format!(
            "math.{}({}, {})",
            rng.pick(&["max", "min", "fmod"]),
            expression(rng, depth - 1),
            expression(rng, depth - 1)
        ),
        5 => format!(
            "string.sub('hello', {}, {})",
            rng.pick(&["1", "2", "-2", "0", "10", "2.0"]),
            rng.pick(&["-1", "3", "1", "2.0", "-10"])
        ),
        _ => format!(
            "({} {} {})",
            expression(rng, depth - 1),
            rng.pick(BINARY),
            expression(rng, depth - 1)
        ),
    }
}

/// Ours: `type tostring`, or `err`.
fn ours(expr: &str, env: &Env<'_>) -> String {
    let Ok(chunk) = parse_script(&format!("return {expr}")) else {
        return "err".to_string();
    };
    match run(&chunk, env) {
        Err(_) => "err".to_string(),
        Ok(values) => {
            let v = values.into_iter().next().unwrap_or(Val::Nil);
            let text = super::library::call("tostring", std::slice::from_ref(&v))
                .ok()
                .flatten();
            match text {
                Some(Val::Str(s)) => format!("{} {}", v.type_name(), String::from_utf8_lossy(&s)),
                _ => "err".to_string(),
            }
        }
    }
}

#[test]
fn expressions_evaluate_as_in_lua_5_3() {
    // Five programs of 4 000 expressions each (one Lua chunk holds no more).
    for seed in 0..5u64 {
        if !batch(0x5eed_1234_abcd_0043 ^ (seed << 32)) {
            return;
        }
    }
}

/// One program of expressions from `seed`; false when there is no lua5.3.
fn batch(seed: u64) -> bool {
    let Ok(mut child) = Command::new("lua5.3")
        .arg("-")
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
    else {
        println!("SKIPPED: no lua5.3 on the PATH (Debian's lua5.3) to compare the evaluator with");
        return false;
    };
    let mut rng = Rng(seed);
    let expressions: Vec<String> = (0..4000).map(|_| expression(&mut rng, 4)).collect();
    let mut program = String::new();
    for e in &expressions {
        program.push_str(&format!(
            "do local ok, v = pcall(function() return {e} end) \
             if ok then print(type(v) .. ' ' .. tostring(v)) else print('err') end end\n"
        ));
    }
    {
        let mut stdin = child.stdin.take().expect("stdin");
        stdin
            .write_all(program.as_bytes())
            .expect("program written");
    }
    let output = child.wait_with_output().expect("lua5.3 runs");
    let lua = String::from_utf8_lossy(&output.stdout);
    let lua: Vec<&str> = lua.lines().collect();
    assert_eq!(
        lua.len(),
        expressions.len(),
        "one line per expression from lua5.3"
    );
    let desc = protos::DESCRIPTOR_POOL
        .all_messages()
        .next()
        .expect("a message type");
    let env = Env {
        this: Node::Empty(desc.clone()),
        root: Node::Empty(desc),
        index: 1,
    };
    let mut differences = Vec::new();
    for (e, want) in expressions.iter().zip(&lua) {
        let got = ours(e, &env);
        // NaN's sign in `tostring` is the C library's, not Lua's: either.
        let same = got == *want || (got.ends_with("nan") && want.ends_with("nan"));
        if !same {
            differences.push(format!("{e}: ours {got}, lua5.3 {want}"));
        }
    }
    println!(
        "{} expressions compared with lua5.3, {} differ",
        expressions.len(),
        differences.len()
    );
    assert!(
        differences.is_empty(),
        "{}",
        differences[..differences.len().min(25)].join("\n")
    );
    true
}
