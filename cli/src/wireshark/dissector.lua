-- The decoder of the dissector `goby dccl wireshark` writes: the SCHEMA
-- above it says which DCCL messages there are and how each field is coded;
-- this reads them as DCCL's default codecs write them (fields packed least
-- significant bit first, the header padded to whole bytes, the body after
-- it) and shows each message as `goby dccl decode` prints it. Written for
-- the Lua of Wireshark 3.x and 4.x (5.2 to 5.4): numbers are doubles or
-- integers, no bitwise operator is used, 64-bit values go through Int64
-- and UInt64. Dynamic conditions run in this Lua, on the message decoded
-- so far, as `goby dccl decode` evaluates them.

local TWO32 = 4294967296

-- Bit reader over bytes[first .. last] (0-based offsets into a ByteArray).
local Reader = {}
Reader.__index = Reader

local function reader(bytes, first, last)
  return setmetatable({ bytes = bytes, first = first, nbits = (last - first) * 8, pos = 0 }, Reader)
end

-- The next n bits (at most 32) as a number, least significant bit first.
function Reader:small(n)
  if self.pos + n > self.nbits then
    error("the message ends before its last field", 0)
  end
  local value, scale, got = 0, 1, 0
  while got < n do
    local at = self.first + math.floor(self.pos / 8)
    local shift = self.pos % 8
    local take = math.min(8 - shift, n - got)
    local chunk = math.floor(self.bytes:get_index(at) / 2 ^ shift) % 2 ^ take
    value = value + chunk * scale
    scale = scale * 2 ^ take
    got = got + take
    self.pos = self.pos + take
  end
  return value
end

-- The next n bits as (low 32 bits, the bits above them), both exact.
function Reader:wide(n)
  if n <= 32 then
    return self:small(n), 0
  end
  local low = self:small(32)
  return low, self:small(n - 32)
end

function Reader:bit()
  return self:small(1) == 1
end

-- n whole bytes (from any bit), as a Lua string.
function Reader:bytes_n(n)
  local out = {}
  for i = 1, n do
    out[i] = string.char(self:small(8))
  end
  return table.concat(out)
end

-- Numbers as the C++ protobuf library prints them.
local function g_format(v, digits)
  if v ~= v then return "nan" end
  if v == math.huge then return "inf" end
  if v == -math.huge then return "-inf" end
  if v == 0 then
    if 1 / v < 0 then return "-0" end
    return "0"
  end
  return string.format("%." .. digits .. "g", v)
end

local function double_text(v)
  local short = g_format(v, 15)
  if tonumber(short) == v then return short end
  return g_format(v, 17)
end

-- A double rounded to the nearest float (ties to even).
local function to_f32(x)
  if string.pack then
    return (string.unpack("<f", string.pack("<f", x)))
  end
  if x == 0 or x ~= x or x == math.huge or x == -math.huge then return x end
  local m, e = math.frexp(x)
  local scaled = m * 2 ^ 24
  local r = math.floor(scaled + 0.5)
  if r - scaled == 0.5 and r % 2 == 1 then r = r - 1 end
  return r * 2 ^ (e - 24)
end

local function float_text(v)
  local short = g_format(v, 6)
  local back = tonumber(short)
  if back ~= nil and to_f32(back) == v then return short end
  return g_format(v, 9)
end

local function int_text(v)
  return string.format("%.0f", v)
end

-- Bytes as protobuf's C escaping writes them.
local ESCAPES = { [10] = "\\n", [13] = "\\r", [9] = "\\t", [34] = '\\"', [39] = "\\'", [92] = "\\\\" }
local function c_escape(s)
  local out = {}
  for i = 1, #s do
    local b = s:byte(i)
    if ESCAPES[b] then
      out[#out + 1] = ESCAPES[b]
    elseif b >= 32 and b <= 126 then
      out[#out + 1] = string.char(b)
    else
      out[#out + 1] = string.format("\\%03o", b)
    end
  end
  return '"' .. table.concat(out) .. '"'
end

-- Bytes as UTF-8 text, each maximal invalid part replaced by U+FFFD (as
-- a string decoded by goby is).
local function utf8_lossy(s)
  local out, i, n = {}, 1, #s
  while i <= n do
    local b = s:byte(i)
    local len, lo, hi = 0, 0x80, 0xBF
    if b < 0x80 then len = 1
    elseif b >= 0xC2 and b <= 0xDF then len = 2
    elseif b >= 0xE0 and b <= 0xEF then
      len = 3
      if b == 0xE0 then lo = 0xA0 elseif b == 0xED then hi = 0x9F end
    elseif b >= 0xF0 and b <= 0xF4 then
      len = 4
      if b == 0xF0 then lo = 0x90 elseif b == 0xF4 then hi = 0x8F end
    end
    if len == 0 then
      out[#out + 1] = "\239\191\189"
      i = i + 1
    else
      local good = 1
      for k = 1, len - 1 do
        local c = s:byte(i + k)
        local min, max = 0x80, 0xBF
        if k == 1 then min, max = lo, hi end
        if c == nil or c < min or c > max then break end
        good = good + 1
      end
      if good == len then
        out[#out + 1] = s:sub(i, i + len - 1)
      else
        out[#out + 1] = "\239\191\189"
      end
      i = i + good
    end
  end
  return table.concat(out)
end

-- The arithmetic of DCCL's default numeric codec (dccl's numeric.rs).
local function round_half_up(d)
  return math.floor(d + 0.5)
end

local function trunc(d)
  if d >= 0 then return math.floor(d) end
  return -math.floor(-d)
end

local function mul_res(c, x)
  if c.unit then return x end
  return x * c.res
end

local function div_res(c, x)
  if c.unit then return x end
  if c.rr then return x * c.rr end
  return x / c.res
end

local function div_inv(c, x)
  if c.ir then return x * c.ir end
  return x / c.inv
end

local function steps_value(c, s)
  if c.res >= 1 then return mul_res(c, s) end
  return div_inv(c, s)
end

local function quantize_f64(c, v)
  local s
  if c.res >= 1 then s = round_half_up(div_res(c, v)) else s = round_half_up(v * c.inv) end
  return steps_value(c, s)
end

-- An integer value rounded to a multiple of an integer resolution.
local function quantize_int(c, v)
  local res = c.res
  if res - math.floor(res) >= 2.220446049250313e-16 then return v end
  local step = math.floor(res)
  local rem = v - step * trunc(v / step)
  local q = v - rem
  if rem >= res / 2 then q = q + res end
  return q
end

-- An integer of Lua 5.3 (and later) when it has one of that value.
local toint = math.tointeger or function(x) return x end

-- The integer written `text`, as a Lua integer in Lua 5.3 and later
-- (wrapping past 2^63, as a 64-bit field's value converts), else a double.
local function int_of_text(text)
  if math.tointeger == nil then return tonumber(text) end
  local v, neg = 0, text:sub(1, 1) == "-"
  for i = neg and 2 or 1, #text do
    v = v * 10 + (text:byte(i) - 48)
  end
  if neg then v = -v end
  return v
end

-- The value of wire number u (presence already taken off): its text and
-- its Lua value (an integer, or a float).
local function numeric_text(c, low, high)
  local t = c.t
  if c.wide then
    -- 64-bit integers of resolution 1: exact with Int64 / UInt64 (the
    -- value read wider than a double's mantissa goes through a double,
    -- as in the codec).
    local u
    if t == "i64" and high >= 2 ^ 31 then
      u = (high - TWO32) * TWO32 + low
    else
      u = high * TWO32 + low
    end
    local text
    if t == "i64" then
      if high < 2 ^ 20 then
        text = tostring(Int64.new(low, high) + Int64.new(c.min))
      else
        text = tostring(Int64.new(u) + Int64.new(c.min))
      end
    elseif high < 2 ^ 20 then
      text = tostring(UInt64.new(low, high) + UInt64.new(c.min))
    else
      text = tostring(UInt64.new(u) + UInt64.new(c.min))
    end
    return text, int_of_text(text)
  end
  local u = low
  local v
  if t == "f64" then
    if c.k0 and u < 2 ^ 43 then
      v = steps_value(c, u + c.k0)
    else
      local w
      if c.res >= 1 then w = mul_res(c, u) else w = div_inv(c, u) end
      v = quantize_f64(c, w + c.min)
    end
    return double_text(v), v + 0.0
  elseif t == "f32" then
    local w = to_f32(u)
    if c.res >= 1 then w = to_f32(mul_res(c, w)) else w = to_f32(div_inv(c, w)) end
    v = to_f32(quantize_f64(c, to_f32(w + c.min)))
    return float_text(v), v + 0.0
  end
  if c.unit then
    v = u + c.min
  else
    local w
    if c.res >= 1 then w = trunc(mul_res(c, u)) else w = trunc(div_inv(c, u)) end
    v = quantize_int(c, w + c.min)
  end
  return int_text(v), toint(v)
end

-- Reads a numeric wire value: nil when "not present".
local function read_numeric(c, r)
  local low, high = r:wide(c.bits)
  if not c.req then
    if low == 0 and high == 0 then return nil end
    if low == 0 then low, high = TWO32 - 1, high - 1 else low = low - 1 end
  end
  return low, high
end

-- The time codec's time of day made a time near the capture's (seconds).
local function time_text(c, tod, now)
  local span = c.span
  local daystart = now - now % span
  local today = now - daystart
  local half = math.floor(span / 2)
  if tod - today > half then
    daystart = daystart - span
  elseif today - tod > half then
    daystart = daystart + span
  end
  local scaled = c.conv * (daystart + tod)
  local round_to = c.round_to
  if c.tt == "s" then
    local scaling = 10 ^ round_to
    local v = round_half_up(scaled * scaling) / scaling
    return double_text(v), v + 0.0
  end
  local v = trunc(scaled)
  if round_to < 0 then
    local scaling = 10 ^ -round_to
    local rem = v - scaling * trunc(v / scaling)
    v = v - rem
    if rem >= scaling / 2 then v = v + scaling end
  end
  if c.tt == "u64" and v < 0 then v = 0 end
  return int_text(v), toint(v)
end

local decode_part

-- One value of codec c: its text (a message table for a message), or nil
-- when not present; then its value as dynamic conditions see it.
local function decode_value(c, r, ctx, existing)
  if c.pbit and not r:bit() then return nil end
  local k = c.k
  if k == "num" then
    local low, high = read_numeric(c, r)
    if low == nil then return nil end
    return numeric_text(c, low, high)
  elseif k == "time" then
    local low = read_numeric(c, r)
    if low == nil then return nil end
    local tod = tonumber((numeric_text(c, low, 0)))
    return time_text(c, tod, ctx.now)
  elseif k == "bool" then
    local v
    if c.req then
      v = r:small(1) == 1
    else
      local w = r:small(2)
      if w == 0 then return nil end
      v = w - 1 ~= 0
    end
    return v and "true" or "false", v
  elseif k == "enum" then
    local low = read_numeric(c, r)
    if low == nil then return nil end
    local w = low + c.min
    local number = w
    if c.packed then number = c.numbers[w + 1] end
    if number == nil then return nil end
    local name = c.names[number]
    return name, name
  elseif k == "str2" then
    local len = r:small(c.prefix)
    if len == 0 then return nil end
    local s = utf8_lossy(r:bytes_n(len))
    return c_escape(s), s
  elseif k == "fixb" then
    if not c.req and not r:bit() then return nil end
    local s = r:bytes_n(c.maxlen)
    return c_escape(s), s
  elseif k == "varb" then
    if not c.req and not r:bit() then return nil end
    local s = r:bytes_n(r:small(c.prefix))
    if c.str then s = utf8_lossy(s) end
    return c_escape(s), s
  elseif k == "static" then
    return c.text, c.val
  elseif k == "id" then
    local v
    if r:small(1) == 1 then v = r:small(15) else v = r:small(7) end
    return int_text(v), toint(v)
  elseif k == "msg" then
    if c.presence and not r:bit() then return existing end
    local value = existing or {}
    decode_part(c, r, value, ctx)
    if c.v < 3 and next(value) == nil then return existing end
    return value
  end
  error("no decoder for codec " .. tostring(k), 0)
end

-- The fields of one part of a message (its header or its body, or an
-- embedded message) into `value` (field number -> text, table, or list).
decode_part = function(part, r, value, ctx)
  local cases = {}
  for i, bits in ipairs(part.oneofs or {}) do
    cases[i] = r:small(bits)
  end
  for _, e in ipairs(part.fields) do
    if e.oneof and cases[e.oneof[1]] ~= e.oneof[2] then
      -- another member of the oneof is set
    elseif e.rep then
      local count = e.rep.max
      if e.rep.counted then count = r:small(e.rep.bits) + e.rep.min end
      local list, empties = {}, 0
      for _ = 1, count do
        local v = decode_value(e.c, r, ctx, nil)
        if v ~= nil then
          list[#list + 1] = v
        elseif e.c.k == "msg" then
          list[#list + 1] = {}
          empties = empties + 1
        end
      end
      for i = #list, count - empties + 1, -1 do list[i] = nil end
      if #list > 0 then
        local all = value[e.n] or {}
        for _, v in ipairs(list) do all[#all + 1] = v end
        value[e.n] = all
      end
    else
      local v = decode_value(e.c, r, ctx, value[e.n])
      if v ~= nil then value[e.n] = v end
    end
  end
end

-- Dynamic conditions (`(dccl.field).dynamic_conditions`): each script of
-- SCHEMA.scripts is compiled once, in an environment holding what DCCL
-- conditions may use, and run with `this`, `root` and `this_index` as the
-- decoder of `goby dccl decode` gives them: the messages as decoded so far
-- (a message being decoded seen in its place; in a repeated field of
-- messages, as many elements as max_repeat, empty past the one being
-- decoded), unset fields as their default or nil, enums as names, repeated
-- fields as arrays (nil when empty), a oneof's name as the name of its
-- member set, and `this_index` the index, from 1, of the element of the
-- last repeated field decoded.

-- Side tables of each decoded message table (whose number keys hold the
-- fields' texts): its type, the values conditions see, the field being
-- decoded in it.
local TYPE_OF = setmetatable({}, { __mode = "k" })
local VALUES_OF = setmetatable({}, { __mode = "k" })
local HOLE_OF = setmetatable({}, { __mode = "k" })
local VIEW_OF = setmetatable({}, { __mode = "k" })

local function new_message(type_name)
  local t = {}
  TYPE_OF[t] = type_name
  VALUES_OF[t] = {}
  return t
end

-- Each type's fields by name, and its oneofs by name.
local FIELDS_BY_NAME = {}
for type_name, fields in pairs(SCHEMA.types) do
  local by_name = {}
  for _, f in ipairs(fields) do by_name[f.name] = f end
  FIELDS_BY_NAME[type_name] = by_name
end

local view

local function element_view(f, item, value)
  if f.msg then return view(item, f.msg) end
  return value
end

-- A repeated field as an array.
local function list_view(f, get, len)
  return setmetatable({}, {
    __index = function(_, k)
      if type(k) ~= "number" or k ~= math.floor(k) or k < 1 or k > len then return nil end
      return get(k)
    end,
    __len = function() return len end,
    __newindex = function() error("a message is read only in DCCL conditions", 2) end,
  })
end

-- The value of the field named `key` of message table `msg`.
local function field_value(msg, key)
  local type_name = TYPE_OF[msg]
  if type(key) ~= "string" then return nil end
  local f = FIELDS_BY_NAME[type_name][key]
  local hole = HOLE_OF[msg]
  if f == nil then
    local members = SCHEMA.oneofs[type_name] and SCHEMA.oneofs[type_name][key]
    if members == nil then return nil end
    for _, m in ipairs(members) do
      if (hole and hole.n == m.n) or msg[m.n] ~= nil then return m.name end
    end
    return nil
  end
  if hole and hole.n == f.n then
    if not hole.list then return view(hole.child, f.msg) end
    local before = hole.list
    return list_view(f, function(i)
      if i <= #before then return view(before[i], f.msg) end
      if i == hole.index + 1 then return view(hole.child, f.msg) end
      return view(new_message(f.msg), f.msg)
    end, hole.shown)
  end
  local values = VALUES_OF[msg]
  if f.list then
    local items = msg[f.n]
    if items == nil or #items == 0 then return nil end
    local vals = values[f.n]
    return list_view(f, function(i) return element_view(f, items[i], vals and vals[i]) end, #items)
  end
  if f.msg then
    if msg[f.n] == nil then return nil end
    return view(msg[f.n], f.msg)
  end
  local v = values[f.n]
  if v == nil then return f.def end
  return v
end

-- A message table as conditions see it (the same table each time).
view = function(msg, type_name)
  local v = VIEW_OF[msg]
  if v ~= nil then return v end
  TYPE_OF[msg] = TYPE_OF[msg] or type_name
  VALUES_OF[msg] = VALUES_OF[msg] or {}
  v = setmetatable({}, {
    __index = function(_, key) return field_value(msg, key) end,
    __newindex = function() error("a message is read only in DCCL conditions", 2) end,
  })
  VIEW_OF[msg] = v
  return v
end

-- What the scripts may use, as in DCCL conditions (print writes nothing).
local ENV = {
  print = function() end,
  type = type,
  tonumber = function(v, base)
    if base ~= nil then error("tonumber with a base is not supported in DCCL conditions", 2) end
    return tonumber(v)
  end,
  tostring = function(v)
    local t = type(v)
    if t == "table" or t == "function" then
      error("tostring of a table or function is not supported in DCCL conditions", 2)
    end
    return tostring(v)
  end,
  math = {},
  string = {},
}
for _, k in ipairs({ "abs", "ceil", "floor", "fmod", "huge", "max", "min", "maxinteger",
                     "mininteger", "pi", "sqrt", "tointeger", "type" }) do
  ENV.math[k] = math[k]
end
for _, k in ipairs({ "len", "lower", "sub", "upper" }) do ENV.string[k] = string[k] end

-- Lua 5.2 (no integer subtype) runs a script as Lua 5.3 does unless the
-- schema says why not (`v53`).
local LUA52 = math.type == nil

for _, s in ipairs(SCHEMA.scripts) do
  local fn, err = load(s.code, "=" .. s.kind, "t", ENV)
  s.fn, s.load_error = fn, err
end

local function script_error(s, why)
  return 'field ' .. s.field .. ': dynamic_conditions.' .. s.kind .. ' "' .. s.src .. '" ' .. why
end

-- The first value script `i` returns, with `this` the message table
-- `this_msg` (of type `this_type`).
local function run(i, this_msg, this_type, ctx)
  local s = SCHEMA.scripts[i]
  if LUA52 and s.v53 then
    error(script_error(s, "needs Lua 5.3 (" .. s.v53 .. "); this Wireshark's Lua is 5.2"), 0)
  end
  if s.fn == nil then
    error(script_error(s, "cannot be run by this Wireshark's Lua: " .. tostring(s.load_error)), 0)
  end
  ENV.this = view(this_msg, this_type)
  ENV.root = view(ctx.root, ctx.root_type)
  ENV.this_index = toint(ctx.index + 1)
  local ok, v = pcall(s.fn)
  if not ok then
    -- Without Lua's "kind:line:" before the reason, as the codec tells it.
    local why = tostring(v):gsub("^" .. s.kind .. ":%d+: ", "")
    error(script_error(s, "failed: " .. why), 0)
  end
  return v
end

local function truth(i, this_msg, this_type, ctx)
  local v = run(i, this_msg, this_type, ctx)
  return v ~= nil and v ~= false
end

-- A bound script's number (numeric strings converted).
local function bound(i, this_msg, this_type, ctx)
  local v = run(i, this_msg, this_type, ctx)
  local n = v
  if type(v) == "string" then n = tonumber(v) end
  local s = SCHEMA.scripts[i]
  if type(n) ~= "number" then
    local shown = tostring(v)
    if type(v) == "string" then shown = '"' .. v .. '" (a string)'
    elseif type(v) == "boolean" then shown = shown .. " (a boolean)"
    elseif type(v) == "table" then shown = "a table" end
    error(script_error(s, "failed: gave " .. shown .. ", not a number"), 0)
  end
  if n ~= n then error(script_error(s, "failed: gave NaN"), 0) end
  return n
end

-- ceil(log2(v)) of a whole number v >= 0.
local function ceil_log2(v)
  local bits = 0
  while 2 ^ bits < v do bits = bits + 1 end
  return bits
end

-- The numeric codec c with the bounds [min, max] in force (what dccl's
-- NumericBounds derives from them: size, minimum, steps of the minimum).
local function with_bounds(c, min, max)
  local n = {}
  for k, v in pairs(c) do n[k] = v end
  local null = c.req and 0 or 1
  n.bits = ceil_log2(math.ceil((max - min) / c.res + 1 + null))
  n.k0 = nil
  local t = c.t
  if t == "f64" then
    n.min = quantize_f64(c, min)
    local steps = function(x)
      if c.res >= 1 then return round_half_up(div_res(c, x)) end
      return round_half_up(x * c.inv)
    end
    local k0, k1 = steps(min), steps(max)
    if n.bits <= 43 and math.abs(k0) < 2 ^ 43 and math.abs(k1) < 2 ^ 43
        and math.max(math.abs(min), math.abs(max)) < math.huge then
      n.k0 = k0
    end
  elseif t == "f32" then
    n.min = to_f32(quantize_f64(c, to_f32(min)))
  else
    n.min = quantize_int(c, trunc(min))
  end
  return n
end

-- The codec of field entry e with its bounds in force.
local function bounded(e, c, this_msg, this_type, ctx)
  local d = e.dyn
  local min, max = d.smin, d.smax
  if d.min then min = math.min(d.smax, math.max(bound(d.min, this_msg, this_type, ctx), d.smin)) end
  if d.max then max = math.max(d.smin, math.min(bound(d.max, this_msg, this_type, ctx), d.smax)) end
  if min > max then
    error("field " .. SCHEMA.scripts[d.min or d.max].field .. ": dynamic_conditions give the bounds [" .. min .. ", " .. max .. "]: the minimum is over the maximum", 0)
  end
  return with_bounds(c, min, max)
end

-- Whether the conditions of entry e leave it (or an element) out.
local function omitted(e, this_msg, this_type, ctx)
  local d = e.dyn
  if d == nil or d.omit == nil then return false end
  local v = truth(d.omit, this_msg, this_type, ctx)
  if d.neg then return not v end
  return v
end

-- The codec of entry e: its required one when a condition says so.
local function chosen(e, this_msg, this_type, ctx)
  local d = e.dyn
  if d and d.req and truth(d.req, this_msg, this_type, ctx) then return d.rc end
  return e.c
end

local function has_fields(t)
  for k in pairs(t) do
    if type(k) == "number" then return true end
  end
  return false
end

local decode_part_dyn

-- A singular embedded message under its conditions.
local function decode_child_dyn(e, r, value, type_name, ctx)
  local child = value[e.n] or new_message(e.c.t)
  value[e.n] = nil
  if omitted(e, value, type_name, ctx) then
    if has_fields(child) then value[e.n] = child end
    return
  end
  HOLE_OF[value] = { n = e.n, child = child }
  local c = e.c
  if e.dyn and e.dyn.req then
    c = chosen(e, child, e.c.t, ctx)
  end
  if c.presence and not r:bit() then
    HOLE_OF[value] = nil
    return
  end
  decode_part_dyn(c, r, child, ctx)
  HOLE_OF[value] = nil
  if c.v > 2 or has_fields(child) then value[e.n] = child end
end

-- A repeated field, element by element under its conditions.
local function decode_repeated_dyn(e, r, value, type_name, ctx)
  local count = e.rep.max
  if e.rep.counted then count = r:small(e.rep.bits) + e.rep.min end
  local list, vals, empties = {}, {}, 0
  for i = 0, count - 1 do
    ctx.index = i
    if e.c.k == "msg" then
      if i >= e.rep.max then
        -- One more decodes only when its conditions leave it out.
        HOLE_OF[value] = nil
        if not omitted(e, value, type_name, ctx) then
          error(count .. " elements, over max_repeat " .. e.rep.max, 0)
        end
      else
        local element = new_message(e.c.t)
        HOLE_OF[value] = { n = e.n, list = list, index = i, shown = e.rep.max, child = element }
        if not omitted(e, element, e.c.t, ctx) then
          decode_part_dyn(e.c, r, element, ctx)
        end
        if e.c.v < 3 and not has_fields(element) then empties = empties + 1 end
        list[#list + 1] = element
      end
    elseif not omitted(e, value, type_name, ctx) then
      local c = e.c
      if e.dyn and e.dyn.smin then c = bounded(e, c, value, type_name, ctx) end
      local text, v = decode_value(c, r, ctx, nil)
      if text ~= nil then
        list[#list + 1] = text
        vals[#list] = v
      end
    end
  end
  HOLE_OF[value] = nil
  for i = #list, #list - empties + 1, -1 do
    list[i] = nil
    vals[i] = nil
  end
  if #list > 0 then
    value[e.n] = list
    VALUES_OF[value][e.n] = vals
  end
end

-- The fields of one part of a message of a type with conditions into the
-- message table `value` (as decode_part, each field under its conditions).
decode_part_dyn = function(part, r, value, ctx)
  local type_name = part.t
  TYPE_OF[value] = TYPE_OF[value] or type_name
  VALUES_OF[value] = VALUES_OF[value] or {}
  local cases = {}
  for i, bits in ipairs(part.oneofs or {}) do
    cases[i] = r:small(bits)
  end
  for _, e in ipairs(part.fields) do
    if e.rep then
      decode_repeated_dyn(e, r, value, type_name, ctx)
    elseif e.oneof and cases[e.oneof[1]] ~= e.oneof[2] then
      -- another member of the oneof is set
    elseif e.c.k == "msg" then
      decode_child_dyn(e, r, value, type_name, ctx)
    elseif not omitted(e, value, type_name, ctx) then
      local c = chosen(e, value, type_name, ctx)
      if e.dyn and e.dyn.smin then c = bounded(e, c, value, type_name, ctx) end
      local text, v = decode_value(c, r, ctx, nil)
      if text ~= nil then
        value[e.n] = text
        VALUES_OF[value][e.n] = v
      end
    end
  end
end

-- The fields of a decoded message as `goby dccl decode` prints them, in
-- number order, one "name: value" or "name { ... }" each.
local function field_texts(type_name, value)
  local parts = {}
  for _, f in ipairs(SCHEMA.types[type_name]) do
    local v = value[f.n]
    if v ~= nil then
      local items = v
      if not f.list then items = { v } end
      for _, item in ipairs(items) do
        if f.msg then
          local inner = table.concat(field_texts(f.msg, item), " ")
          if inner ~= "" then inner = " " .. inner end
          parts[#parts + 1] = f.name .. " {" .. inner .. " }"
        else
          parts[#parts + 1] = f.name .. ": " .. item
        end
      end
    end
  end
  return parts
end

local dccl = Proto("dccl", "DCCL (goby-rs)")
local pf = {
  message = ProtoField.string("dccl.message", "Message"),
  type = ProtoField.string("dccl.type", "Type"),
  id = ProtoField.uint32("dccl.id", "DCCL id"),
  field = ProtoField.string("dccl.field", "Field"),
  error = ProtoField.string("dccl.error", "Not decoded"),
  padding = ProtoField.bytes("dccl.padding", "Padding"),
}
dccl.fields = { pf.message, pf.type, pf.id, pf.field, pf.error, pf.padding }

-- The DCCL id at the start of bytes[at ..]: (id, bytes it takes).
local function read_id(bytes, at, last)
  local r = reader(bytes, at, last)
  if r:small(1) == 1 then
    r.pos = 0
    return math.floor(r:small(16) / 2), 2
  end
  r.pos = 0
  return math.floor(r:small(8) / 2), 1
end

-- Decodes one message at bytes[at ..]: its bytes, type and value.
local function decode_message(bytes, at, last, ctx)
  local id = read_id(bytes, at, last)
  local m = SCHEMA.messages[id]
  if m == nil then
    error("DCCL id " .. id .. " is not one of the dissector's messages", 0)
  end
  if m.refused then
    error(m.name .. " (DCCL id " .. id .. "): " .. m.refused, 0)
  end
  if last - at < m.head_bytes then
    error(m.name .. ": the message ends inside its header (" .. (last - at) .. " of " .. m.head_bytes .. " bytes)", 0)
  end
  local value = new_message(m.name)
  local decode = decode_part
  if m.dyn then
    -- Conditions see the message from its root, this_index from 1.
    decode = decode_part_dyn
    ctx.root, ctx.root_type, ctx.index = value, m.name, 0
  end
  local head = reader(bytes, at, at + m.head_bytes)
  head.pos = m.id_bits
  local ok, err = pcall(decode, m.head, head, value, ctx)
  if not ok then error(m.name .. ": " .. err, 0) end
  local body = reader(bytes, at + m.head_bytes, last)
  ok, err = pcall(decode, m.body, body, value, ctx)
  if not ok then error(m.name .. ": " .. err, 0) end
  return m.head_bytes + math.ceil(body.pos / 8), m, id, value
end

local function all_zero(bytes, from, last)
  for i = from, last - 1 do
    if bytes:get_index(i) ~= 0 then return false end
  end
  return true
end

-- Every message of a frame (DCCL messages back to back, maybe zero
-- padding after them), each a subtree with its text and fields.
local function dissect_frame(tvb, tree, ctx)
  local bytes = tvb:bytes()
  local last = bytes:len()
  local at, count = 0, 0
  while at < last do
    if count > 0 and all_zero(bytes, at, last) then
      tree:add(pf.padding, tvb(at, last - at))
      break
    end
    local ok, len, m, id, value = pcall(decode_message, bytes, at, last, ctx)
    if not ok then
      tree:add(pf.error, tvb(at, last - at), len)
      break
    end
    local fields = field_texts(m.name, value)
    local text = table.concat(fields, " ")
    local sub = tree:add(dccl, tvb(at, len), m.name .. ": " .. text)
    sub:add(pf.type, tvb(at, len), m.name)
    sub:add(pf.id, tvb(at, len), id)
    sub:add(pf.message, tvb(at, len), text)
    for _, field in ipairs(fields) do
      sub:add(pf.field, tvb(at, len), field)
    end
    count = count + 1
    at = at + len
  end
  return count
end

-- Goby's UDP driver: each datagram a protobuf goby.acomms.protobuf.ModemTransmission.
local goby_udp = Proto("goby_udp", "Goby UDP driver (ModemTransmission)")
local TYPES = { [1] = "DATA", [2] = "ACK", [10] = "DRIVER_SPECIFIC" }
local uf = {
  src = ProtoField.int32("goby_udp.src", "Source"),
  dest = ProtoField.int32("goby_udp.dest", "Destination"),
  time = ProtoField.string("goby_udp.time", "Time (microseconds since 1970)"),
  type = ProtoField.string("goby_udp.type", "Type"),
  rate = ProtoField.int32("goby_udp.rate", "Rate"),
  ack_requested = ProtoField.bool("goby_udp.ack_requested", "Ack requested"),
  frame_start = ProtoField.uint32("goby_udp.frame_start", "First frame"),
  acked_frame = ProtoField.int32("goby_udp.acked_frame", "Acknowledged frame"),
  unique_id = ProtoField.uint32("goby_udp.unique_id", "Unique id"),
  max_num_frames = ProtoField.uint32("goby_udp.max_num_frames", "Most frames"),
  max_frame_bytes = ProtoField.uint32("goby_udp.max_frame_bytes", "Most bytes a frame"),
  slot_seconds = ProtoField.double("goby_udp.slot_seconds", "Slot (s)"),
  slot_index = ProtoField.int32("goby_udp.slot_index", "Slot index"),
  frame = ProtoField.bytes("goby_udp.frame", "Frame"),
  frame_identity = ProtoField.bytes("goby_udp.frame_identity", "Frame identity (gobyd)"),
  other = ProtoField.string("goby_udp.other", "Other field"),
}
goby_udp.fields = { uf.src, uf.dest, uf.time, uf.type, uf.rate, uf.ack_requested,
  uf.frame_start, uf.acked_frame, uf.unique_id, uf.max_num_frames, uf.max_frame_bytes,
  uf.slot_seconds, uf.slot_index, uf.frame, uf.frame_identity, uf.other }

-- A varint at bytes[at ..]: (low 32 bits exact, the whole as a double, next offset).
local function varint(bytes, at, last)
  local low, whole, scale = 0, 0, 1
  for i = 0, 9 do
    if at + i >= last then error("a varint runs past the datagram", 0) end
    local b = bytes:get_index(at + i)
    local part = b % 128
    whole = whole + part * scale
    if i < 4 then
      low = low + part * scale
    elseif i == 4 then
      low = low + (part % 16) * scale
    end
    scale = scale * 128
    if b < 128 then return low, whole, at + i + 1 end
  end
  error("a varint longer than 10 bytes", 0)
end

local function int32_of(low)
  if low >= 2 ^ 31 then return low - TWO32 end
  return low
end

function goby_udp.dissector(tvb, pinfo, tree)
  local bytes = tvb:bytes()
  local last = bytes:len()
  local ctx = { now = math.floor(pinfo.abs_ts) }
  local root = tree:add(goby_udp, tvb())
  local at, frames = 0, 0
  local ok, err = pcall(function()
    while at < last do
      local key_low, _, next_at = varint(bytes, at, last)
      local number, wire = math.floor(key_low / 8), key_low % 8
      local start = at
      at = next_at
      if wire == 0 then
        local low, whole
        low, whole, at = varint(bytes, at, last)
        local range = tvb(start, at - start)
        if number == 1 then root:add(uf.src, range, int32_of(low))
        elseif number == 2 then root:add(uf.dest, range, int32_of(low))
        elseif number == 3 then root:add(uf.time, range, int_text(whole))
        elseif number == 6 then root:add(uf.rate, range, int32_of(low))
        elseif number == 7 then root:add(uf.type, range, TYPES[low] or tostring(low))
        elseif number == 13 then root:add(uf.ack_requested, range, low ~= 0)
        elseif number == 15 then root:add(uf.frame_start, range, low)
        elseif number == 20 then root:add(uf.acked_frame, range, int32_of(low))
        elseif number == 31 then root:add(uf.unique_id, range, low)
        elseif number == 11 then root:add(uf.max_num_frames, range, low)
        elseif number == 12 then root:add(uf.max_frame_bytes, range, low)
        elseif number == 33 then root:add(uf.slot_index, range, int32_of(low))
        else root:add(uf.other, range, number .. ": " .. int_text(whole)) end
      elseif wire == 2 then
        local len
        len, _, at = varint(bytes, at, last)
        if at + len > last then error("field " .. number .. " runs past the datagram", 0) end
        if number == 14 and len == 0 then
          root:add(uf.other, tvb(start, at - start), "an empty frame")
        elseif number == 14 then
          local frame = tvb(at, len)
          local sub = root:add(uf.frame, frame)
          frames = frames + dissect_frame(frame:tvb(), sub, ctx)
        elseif number == 37 and len > 0 then
          -- gobyd's identity of a frame's messages, beside the frames.
          local identity = tvb(at, len)
          local sub = root:add(uf.frame_identity, identity)
          frames = frames + dissect_frame(identity:tvb(), sub, ctx)
        elseif number == 20 then
          local p = at
          while p < at + len do
            local low
            local s = p
            low, _, p = varint(bytes, p, at + len)
            root:add(uf.acked_frame, tvb(s, p - s), int32_of(low))
          end
        else
          root:add(uf.other, tvb(start, at + len - start), number .. ": " .. len .. " bytes")
        end
        at = at + len
      elseif wire == 1 or wire == 5 then
        local len = (wire == 1) and 8 or 4
        if at + len > last then error("field " .. number .. " runs past the datagram", 0) end
        if number == 30 and wire == 1 then
          root:add_le(uf.slot_seconds, tvb(at, 8))
        else
          root:add(uf.other, tvb(start, at + len - start), tostring(number))
        end
        at = at + len
      else
        error("wire type " .. wire .. " of field " .. number .. " is not a ModemTransmission's", 0)
      end
    end
  end)
  if not ok then
    root:add(pf.error, tvb(), err)
  end
  pinfo.cols.protocol = "DCCL"
  pinfo.cols.info = "Goby UDP, " .. frames .. " DCCL message(s)"
  return last
end

-- Raw DCCL frames (one a packet), e.g. a pcap of the link's frames.
local dccl_frame = Proto("dccl_frame", "DCCL frame")
function dccl_frame.dissector(tvb, pinfo, tree)
  local sub = tree:add(dccl_frame, tvb())
  local count = dissect_frame(tvb, sub, { now = math.floor(pinfo.abs_ts) })
  pinfo.cols.protocol = "DCCL"
  pinfo.cols.info = count .. " DCCL message(s)"
  return tvb:len()
end

local udp_port = DissectorTable.get("udp.port")
for _, port in ipairs(SCHEMA.udp_ports) do
  udp_port:add(port, goby_udp)
end
if udp_port.add_for_decode_as then
  udp_port:add_for_decode_as(goby_udp)
end
if SCHEMA.user_dlt ~= nil then
  DissectorTable.get("wtap_encap"):add(wtap["USER" .. SCHEMA.user_dlt], dccl_frame)
end
