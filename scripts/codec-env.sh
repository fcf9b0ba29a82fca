# Sourced by the codec scripts: installs what they need when missing (OpenJPEG, WebP and AVIF
# tools from Debian; numpy and Pillow from PyPI) and builds the release DEBT tools.
missing=()
command -v opj_compress >/dev/null || missing+=(libopenjp2-tools)
command -v cwebp >/dev/null || missing+=(webp)
command -v avifenc >/dev/null || missing+=(libavif-bin)
if [ ${#missing[@]} -gt 0 ]; then
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq && apt-get install -y -qq "${missing[@]}"
fi
python3 -c 'import numpy, PIL' 2>/dev/null || python3 -m pip install -q numpy pillow
(cd "$(dirname "${BASH_SOURCE[0]}")/.." && cargo build --release --quiet --bin debt-encode --bin debt-decode)
