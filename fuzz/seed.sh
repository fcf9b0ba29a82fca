#!/usr/bin/env bash
# Recreates the seed corpora of the fuzz targets in fuzz/corpus/<target>/ (git-ignored) from
# wire.md's five test vectors, plus a few forms the vectors do not cover. Safe to rerun: it only
# adds or overwrites its own seed-* files and leaves what the fuzzers added alone.
#
# Usage: fuzz/seed.sh   (from any directory)
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
corpus="$here/corpus"

# Writes the bytes of a hex string to a file.
hex_to_file() {
    local hex="$1" out="$2" esc="" i
    for ((i = 0; i < ${#hex}; i += 2)); do
        esc+="\\x${hex:i:2}"
    done
    printf '%b' "$esc" >"$out"
}

# wire.md's five frames (the same bytes as testdata/wire-vectors.hex).
frames=(
    5510118080dcff0604b001c702d00367000102032fde # rov: src 1 -> 0, 4-byte trunk
    55010b800564ec008181000000000ccb             # operator: velocity
    55020b44ffff0604b00136016700de57             # operator: goto
    55010b8880190506912c3907d027ffca             # operator: image_settings
    55030b0c0c010e800000000000001bee             # operator: hold_heading
)

# wire.md's five JSON lines (the same text as testdata/wire-vectors.jsonl).
lines=(
    '{"type":"rov","src":1,"dst":0,"ft":true,"lt":false,"st":0,"isn":1,"ci":false,"itsn":0,"rd":true,"eoid":1,"loc":false,"hh":true,"arm":true,"nav":"guided","x_cm":-250,"y_cm":1200,"z_cm":455,"roll_deg":359,"pitch_deg":1,"yaw_deg":180,"trunk":"00010203"}'
    '{"type":"operator","src":0,"dst":1,"oid":1,"clo":false,"eisn":0,"ic":false,"rit":5,"order":{"type":"velocity","vx":100,"vy":-20,"vz":0,"vyaw":-127,"arm":true,"disarm":false,"nav":"stabilize"}}'
    '{"type":"operator","src":0,"dst":2,"oid":0,"clo":true,"eisn":1,"ic":true,"rit":63,"order":{"type":"goto","x_cm":-250,"y_cm":1200,"z_cm":310,"heading_deg":359}}'
    '{"type":"operator","src":0,"dst":1,"oid":1,"clo":false,"eisn":1,"ic":false,"rit":0,"order":{"type":"image_settings","roi":[100,80,420,300],"roi_shift":3,"gray":true,"scale":1,"size_bytes":2000,"trunk_bytes":39}}'
    '{"type":"operator","src":0,"dst":3,"oid":0,"clo":false,"eisn":0,"ic":false,"rit":12,"order":{"type":"hold_heading","heading_deg":270,"enable":true}}'
)
# The forms beyond wire.md that the JSON reader also takes (see src/wire/json.rs).
extra_lines=(
    '{"type":"rov","src":2,"dst":0,"ft":false,"lt":false,"st":5,"isn":0,"ci":true,"itsn":7,"status_raw":"010203"}'
    '{"type":"operator","src":0,"dst":15,"oid":0,"clo":false,"eisn":0,"ic":false,"rit":0,"order":{"type":"unknown","ot":7,"body":"000102030405060708"}}'
    '{"type":"raw","src":1,"dst":0,"payload":"deadbeef"}'
)

mkdir -p "$corpus"/{deframe,frame,rov,operator,json_line}

all=""
for i in "${!frames[@]}"; do
    f="${frames[$i]}"
    all+="$f"
    # frame: the whole frame.
    hex_to_file "$f" "$corpus/frame/seed-vector$((i + 1))"
    # deframe: byte 0 = 0 chunk lengths (one push), then the frame.
    hex_to_file "00$f" "$corpus/deframe/seed-vector$((i + 1))"
    # rov / operator: the payload, bytes 3 .. len-2. Source 0 sends operator messages.
    payload="${f:6:${#f}-10}"
    if [[ "${f:2:1}" == 0 ]]; then
        hex_to_file "$payload" "$corpus/operator/seed-vector$((i + 1))"
    else
        hex_to_file "$payload" "$corpus/rov/seed-vector$((i + 1))"
    fi
done
# deframe: all five back to back in one push, and again with garbage, a false preamble, a
# corrupted copy and a cut-off tail, pushed in chunks of 1, 7 and 3 bytes (length bytes: low 7
# bits a length, top bit a flag that makes the deframe target call abandon_incomplete).
hex_to_file "00$all" "$corpus/deframe/seed-all"
hex_to_file "03010703""0013559900""$all""55010b800564ec108181000000000ccb""5510118080dc" \
    "$corpus/deframe/seed-noisy"
# deframe: a false preamble announcing 255 bytes stalls the frames behind it until the deframer
# is told to give up (chunks of 3 and 16 bytes, abandon_incomplete after the second, flag 0x80).
hex_to_file "020390""5502ff""${frames[1]}""${frames[4]}""55010b80" "$corpus/deframe/seed-abandon"
# A ROV message of a reserved status type, and an order of a reserved type.
hex_to_file "0547010203" "$corpus/rov/seed-unknown-status"
hex_to_file "9c00000102030405060708" "$corpus/operator/seed-unknown-order"

# secured_frame: mode byte 0 (the frame as it is), then the secured forms of wire.md's GoTo and
# ROV frames (crates/security/src/vectors.rs: counters 1 and 16385, plain and encrypted); mode 1
# wraps a plain vector's payload in a frame (address byte, payload).
secured=(
    550211200144ffff0604b001360167007218fbe734d1
    550211a0016cc7dc35aa3e5d6066a2341b58bf6cabef
    55101720018080dcff0604b001c702d00367000102037fc944163375
    551017a001e0df28111103f5d9ad30a46abb793b711ca9fed683ac58
)
mkdir -p "$corpus/secured_frame"
for i in "${!secured[@]}"; do
    hex_to_file "00${secured[$i]}" "$corpus/secured_frame/seed-vector$((i + 1))"
done
hex_to_file "0102${frames[2]:6:22}" "$corpus/secured_frame/seed-wrapped-goto"

for i in "${!lines[@]}"; do
    printf '%s' "${lines[$i]}" >"$corpus/json_line/seed-vector$((i + 1))"
done
for i in "${!extra_lines[@]}"; do
    printf '%s' "${extra_lines[$i]}" >"$corpus/json_line/seed-extra$((i + 1))"
done

# debt_decode: streams of the small test images, coded by the release build of debt-encode.
(cd "$here/.." && cargo build --release --quiet --bin debt-encode)
enc="$here/../target/release/debt-encode"
images="$here/../testdata"
mkdir -p "$corpus/debt_decode"
for bytes in 20 60 200 800; do
    "$enc" "$images/kodim23-64x48.png" --bytes "$bytes" -o "$corpus/debt_decode/seed-rgb-$bytes"
    "$enc" "$images/peppers-gray-64.png" --bytes "$bytes" -o "$corpus/debt_decode/seed-gray-$bytes"
done
"$enc" "$images/kodim23-64x48.png" --bytes 300 --roi 8,8,30,20 --roi-shift 4 --scale 1 -o "$corpus/debt_decode/seed-roi"
"$enc" "$images/kodim23-64x48.png" --bytes 100000 --lossless -o "$corpus/debt_decode/seed-lossless"

# link_files: every preset as its model file, one with every netem extra, and a distance track.
(cd "$here/.." && cargo build --release --quiet --bin link-sim)
sim="$here/../target/release/link-sim"
mkdir -p "$corpus/link_files"
for preset in s100 s2cr-burst s2cr-ack satellite-up satellite-down; do
    "$sim" --print-model "$preset" >"$corpus/link_files/seed-$preset.json"
done
"$sim" --print-model s100 --ber 1e-3 --errors corrupt --gilbert-elliott 5,20 --duplicate-percent 10 \
    --corrupt-percent 5 --loss-percent 3 --reorder --rate-limit-bps 900 >"$corpus/link_files/seed-extras.json"
printf 't_s,distance_m\n0,1\n10,6\n20,1\n' >"$corpus/link_files/seed-track.csv"

# evologics: a chunk-length byte, then commands and notifications with binary data.
mkdir -p "$corpus/evologics"
printf '\x05AT*SEND,4,2,ab\r\n\r\nAT*SENDIM,3,2,ack,xyz\r\nAT?T\r\n+++AT*SEND,1,1,q\r\n' >"$corpus/evologics/seed-commands"
printf '\x07RECV,3,1,2,1620,-50,100,670,0.00,a\r\nb\r\nRECVIM,2,2,1,ack,5000,-45,80,0.25,hi\r\nDELIVEREDIM,2\r\nOK\r\nERROR WRONG FORMAT\r\nBUSY BACKOFF\r\n' >"$corpus/evologics/seed-notifications"

# octo_insert: byte 0 picks resolution/max range/colour/raw mode. Clouds as text (issue 14's
# point whose squared length underflows; subnormal, huge and origin points), and raw f32
# triples (origin 0, then -1e-30 x 3 and the smallest subnormal x 3).
mkdir -p "$corpus/octo_insert"
printf '\x01-1e-30 -1e-30 -1e-30\n' >"$corpus/octo_insert/seed-issue14"
printf '\x0d0 0 0\n1e-45 -1e-45 1e-45\n3e38 3e38 3e38\n-3.4e38 0 0\n1 2 3 200 10 10\n' >"$corpus/octo_insert/seed-odd-points"
printf '\x03ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 0 0\n0 1e-30 0\n' >"$corpus/octo_insert/seed-ply"
printf '\x11\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x60\x42\xa2\x8d\x60\x42\xa2\x8d\x60\x42\xa2\x8d\x01\x00\x00\x00\x01\x00\x00\x00\x01\x00\x00\x00' >"$corpus/octo_insert/seed-raw"

echo "seeded $(find "$corpus" -name 'seed-*' | wc -l) files in $corpus"
