#!/usr/bin/env bash
# Create .venv with a torch/torchvision pair that imports together, then crafter-zoo itself.
# A CPU torch beside PyPI's (CUDA) torchvision fails at import ("torchvision::nms does not
# exist"), which breaks open_clip; so torch and torchvision are installed as one matched pair.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  "$PY" -m venv .venv
fi
case "$(uname -m)" in
  aarch64|arm64) TORCH="torch==2.9.1 torchvision==0.24.1" ;;
  *) TORCH="torch==2.14.1 torchvision==0.29.1" ;;
esac
.venv/bin/python -m pip install -q --disable-pip-version-check $TORCH 2>&1 | grep -v "^WARNING: Location" || true
.venv/bin/python -m pip install -q --disable-pip-version-check -e ".[test,rl]" 2>&1 | grep -v "^WARNING: Location" || true
.venv/bin/python -c "import torch, torchvision, open_clip, lightning, jax, crafter, craftax, gymnasium, stable_baselines3, zoo" \
  || { echo "setup.sh: the environment does not import; see the pip output above" >&2; exit 1; }
# Craftax writes its texture cache on first use; two first-time jobs at once (a `zoo data
# generate` beside a `zoo data dagger`) race on that file and one reads it half-written.
.venv/bin/python -c "from craftax.craftax_classic.constants import load_all_textures as t; t()" \
  >/dev/null
echo "setup.sh: .venv ready (torch $(.venv/bin/python -c 'import torch; print(torch.__version__)'))"
