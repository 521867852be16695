#!/usr/bin/env bash
# The protocol decoder's fuzzer under its old name: scripts/fuzz.sh protocol_decoder.
#
#   scripts/fuzz_protocol.sh [SECONDS] [BUILD_DIR]     (defaults: 30, ./build)
exec bash "$(dirname "${BASH_SOURCE[0]}")/fuzz.sh" protocol_decoder "$@"
