# Sourced by the POWERLINK netns tests: writes the concise DCF (CDC) that openCONFIGURATOR would
# write for an MN with one generic CN, the form `powerlink.cdc` reads.
#   write_generic_cdc DIR NODE   → DIR/mnobd.cdc (the MN's file) and DIR/cnNODE.cdc
# The CN's objects: cycle length 1 ms, loss-of-frame tolerance 300 µs, TPDO mapping (disable,
# 2 entries of 64 + 16 bits = 10 bytes PRes payload, enable), PReq limit 4 bytes, the
# configuration's date and time. They stay in
# the array cn_entries (its length is how many objects one configuration run writes).

cdc_le() {  # VALUE BYTES: little-endian bytes as printf escapes
  local v=$1 n=$2 i out=""
  for ((i = 0; i < n; i++)); do out+=$(printf '\\x%02x' $(((v >> (8 * i)) & 0xff))); done
  printf '%s' "$out"
}
cdc_entry() {  # INDEX SUB SIZE VALUE: one concise DCF entry with a numeric value
  printf '%s%s%s%s' "$(cdc_le "$1" 2)" "$(cdc_le "$2" 1)" "$(cdc_le "$3" 4)" "$(cdc_le "$4" "$3")"
}
cdc_map() {  # INDEX SUB OFFSET_BITS LENGTH_BITS: a PDO mapping entry (u64)
  echo $(($1 | ($2 << 16) | ($3 << 32) | ($4 << 48)))
}

# The configuration's date and time as openCONFIGURATOR writes them: the CN's concise DCF sets
# them (0x1020/1, /2), the MN's lists expect them (0x1F26/0x1F27).
generic_conf_date=0x3124
generic_conf_time=0x03735955

write_generic_cdc() {
  local dir=$1 node=$2 e cn_size
  cn_entries=(
    "$(cdc_entry 0x1006 0 4 1000)"
    "$(cdc_entry 0x1C14 0 4 300000)"
    "$(cdc_entry 0x1800 1 1 0)"
    "$(cdc_entry 0x1A00 0 1 0)"
    "$(cdc_entry 0x1A00 1 8 "$(cdc_map 0x6000 1 0 64)")"
    "$(cdc_entry 0x1A00 2 8 "$(cdc_map 0x6000 2 64 16)")"
    "$(cdc_entry 0x1A00 0 1 2)"
    "$(cdc_entry 0x1F98 4 2 4)"
    "$(cdc_entry 0x1020 1 4 "$generic_conf_date")"
    "$(cdc_entry 0x1020 2 4 "$generic_conf_time")"
  )
  { printf "$(cdc_le ${#cn_entries[@]} 4)"; for e in "${cn_entries[@]}"; do printf "$e"; done; } \
      >"$dir/cn$node.cdc"
  cn_size=$(stat -c %s "$dir/cn$node.cdc")
  # The MN's file: its own cycle, the CN's concise DCF (0x1F22/NODE, a domain), the CN's vendor,
  # the configuration date and time it expects the CN to report (0x1F26/0x1F27 /NODE).
  {
    printf "$(cdc_le 5 4)"
    printf "$(cdc_entry 0x1006 0 4 1000)"
    printf "$(cdc_le 0x1F22 2)$(cdc_le "$node" 1)$(cdc_le "$cn_size" 4)"
    cat "$dir/cn$node.cdc"
    printf "$(cdc_entry 0x1F85 "$node" 4 0x1A)"
    printf "$(cdc_entry 0x1F26 "$node" 4 "$generic_conf_date")"
    printf "$(cdc_entry 0x1F27 "$node" 4 "$generic_conf_time")"
  } >"$dir/mnobd.cdc"
}
