#!/bin/bash
# Checks a CAN-I/O capture written by `ds1928ctl --json capture` against the daemon's reply, with
# tools independent of the daemon's writers: tshark (and isb_drops.py, a pcapng reader of its own)
# for pcapng, can-utils for the candump log. Shared by the capture test on the virtual CAN bus
# (capture_canio_test.sh) and the one in the QEMU guest over the kernel's CAN stack
# (tests/canio/qemu/host_check_capture.sh).
#
#   check_can_capture.sh pcapng FILE REPLY_JSON [MIN_FRAMES]
#     every frame decoded by tshark as SocketCAN (LINKTYPE_CAN_SOCKETCAN), none malformed, SYNC
#     (0x080) and the module's objects (CAPTURE_OBJECT_IDS, default 0x281 0x381 0x301) present;
#     per interface: frames in the file = the reply's captured, outbound/inbound (epb_flags) =
#     its tx/rx, captured + dropped = counter_end - counter_start, the Interface Statistics Block
#     the same; two interfaces (cycle port, SDO port); both directions on the cycle port; at
#     least MIN_FRAMES frames (default 1000).
#   check_can_capture.sh candump FILE REPLY_JSON [REPLAYED_LOG]
#     one can-utils log line per frame of the reply, in that format; log2asc reads every line;
#     REPLAYED_LOG (candump -L of a canplayer replay of FILE) holds the same frames, same order.
#
# Prints "ok: ..." lines; exit 0 when everything holds, 1 with "FAIL: ..." otherwise, 77 when a
# tool is missing.
set -u
kind=${1:?pcapng or candump}
file=${2:?capture file}
reply=${3:?reply JSON file}
here=$(cd "$(dirname "$0")" && pwd)
for tool in jq python3 $([ "$kind" = pcapng ] && echo tshark); do
  command -v "$tool" > /dev/null || {
    echo "SKIP: $tool not installed"
    exit 77
  }
done
fail() {
  echo "FAIL: $*"
  exit 1
}
pass() { echo "ok: $*"; }
[ -s "$file" ] || fail "$file is missing or empty"
r=$(jq -ce .capture "$reply" 2> /dev/null) || fail "$reply holds no capture reply: $(head -c 300 "$reply")"

check_pcapng() {
  local min=${1:-1000} errlog total can bad sync objects ids="" id summary="" per_if
  local idx name epbs out inb ifrecv ifdrop i window
  errlog=$(mktemp)
  # One pass for the fields, one for the malformed/erroneous packets (a filter tshark refuses
  # is an error exit, not an empty answer).
  tshark -r "$file" -T fields -E separator=' ' -e frame.interface_id -e can.id \
    > "$errlog.fields" 2> "$errlog"
  sed -i '/Running as user/d' "$errlog"
  [ -s "$errlog" ] && fail "tshark complained: $(head -n 5 "$errlog")"
  bad=$(tshark -r "$file" -Y '_ws.malformed || _ws.expert.severity >= error' 2> "$errlog") ||
    fail "tshark refuses the malformed-packet filter: $(grep -v 'Running as user' "$errlog" | head -n 3)"
  [ -z "$bad" ] || fail "malformed or erroneous frames: $(head -n 5 <<< "$bad")"
  total=$(wc -l < "$errlog.fields")
  # A frame tshark did not decode as CAN has no can.id.
  can=$(awk 'NF >= 2' "$errlog.fields" | wc -l)
  # tshark prints can.id in decimal.
  sync=$(awk '$2 == 128' "$errlog.fields" | wc -l)
  for id in ${CAPTURE_OBJECT_IDS:-0x281 0x381 0x301}; do ids+="$((id)) "; done
  objects=$(awk -v ids=" $ids" 'index(ids, " " $2 " ")' "$errlog.fields" | wc -l)
  per_if=$(awk '{print $1}' "$errlog.fields" | sort | uniq -c | awk '{printf "if%s: %s ", $2, $1}')
  rm -f "$errlog" "$errlog.fields"
  [ "$total" -ge "$min" ] || fail "only $total frames in the file (at least $min expected)"
  [ "$can" = "$total" ] || fail "$can of $total frames decoded as CAN"
  [ "$sync" -gt 0 ] && [ "$objects" -gt 0 ] || fail "SYNC $sync, objects ($ids) $objects"
  [ "$(jq '.interfaces | length' <<< "$r")" = 2 ] || fail "expected 2 interfaces: $r"
  while read -r idx name epbs out inb ifrecv ifdrop; do
    [ "$idx" = x ] && fail "isb_drops.py could not read $file"
    i=$(jq -c ".interfaces[$idx]" <<< "$r")
    window=$(($(jq .counter_end <<< "$i") - $(jq .counter_start <<< "$i")))
    [ "$epbs" = "$(jq .captured <<< "$i")" ] || fail "interface $idx: $epbs frames in the file, reply $i"
    [ "$out" = "$(jq .tx <<< "$i")" ] && [ "$inb" = "$(jq .rx <<< "$i")" ] ||
      fail "interface $idx directions: file $out out / $inb in, reply $i"
    [ $((epbs + $(jq .dropped <<< "$i"))) = "$window" ] || fail "interface $idx: window $window, reply $i"
    [ "$ifrecv" = "$window" ] && [ "$ifdrop" = "$(jq .dropped <<< "$i")" ] ||
      fail "interface $idx ISB: ifrecv $ifrecv ifdrop $ifdrop, reply $i"
    if [ "$idx" = 0 ]; then
      [ "$out" -gt 0 ] && [ "$inb" -gt 0 ] || fail "cycle port: one direction missing (out $out, in $inb)"
    fi
    summary+="$(jq -r .description <<< "$i"): window $window = $epbs in the file (out $out, in $inb) + $ifdrop dropped; "
  done < <(python3 "$here/isb_drops.py" "$file" || echo x)
  pass "pcapng: $total CAN frames (SYNC $sync, objects $objects), none malformed; ${summary}tshark per interface: $per_if"
}

check_candump() {
  local replayed=${1:-} lines asc tmp
  lines=$(wc -l < "$file")
  [ "$lines" = "$(jq .frames <<< "$r")" ] || fail "candump: $lines lines, reply $r"
  [ "$lines" -gt 0 ] || fail "candump: empty log"
  grep -vEq '^\([0-9]{10}\.[0-9]{6}\) [^ ]+ ([0-9A-F]{3}|[0-9A-F]{8})#(([0-9A-F]{2}){0,8}|R)$' "$file" &&
    fail "candump lines not in can-utils log format: $(grep -vE '^\([0-9.]+\) [^ ]+ [0-9A-F]+#([0-9A-F]*|R)$' "$file" | head -n 3)"
  if command -v log2asc > /dev/null; then
    tmp=$(mktemp)
    log2asc -I "$file" -O "$tmp" "$(awk '{print $2; exit}' "$file")" > /dev/null 2>&1 ||
      fail "log2asc refused the log"
    asc=$(grep -cE '^ *[0-9]+\.[0-9]+ ' "$tmp")
    rm -f "$tmp"
    [ "$asc" = "$lines" ] || fail "log2asc read $asc of $lines frames"
    pass "candump log: $lines lines = the reply's frames, all read by can-utils' log2asc ($(head -n 1 "$file"))"
  else
    pass "candump log: $lines lines = the reply's frames, in can-utils log format (log2asc not installed)"
  fi
  [ -n "$replayed" ] || return 0
  # The replay carries another interface name and new time stamps: identifier and data compared.
  cmp -s <(awk '{print $3}' "$file") <(awk '{print $3}' "$replayed") ||
    fail "canplayer's replay differs from the log: $(diff <(awk '{print $3}' "$file") <(awk '{print $3}' "$replayed") | head -n 5) ($(wc -l < "$replayed") frames replayed)"
  pass "canplayer replayed all $lines frames, identifiers and data as logged ($(head -n 1 "$replayed"))"
}

case "$kind" in
  pcapng) check_pcapng "${4:-}" ;;
  candump) check_candump "${4:-}" ;;
  *) fail "unknown kind $kind (pcapng or candump)" ;;
esac
exit 0
