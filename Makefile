# The three commands of cap-ros. Each one sets up what it needs first (fast when nothing changed).
.PHONY: setup test test-fast demo clean

setup:
	bash scripts/setup.sh

test: setup
	bash scripts/test.sh

# Unit tests only: every package's own tests that bring up no graph and no simulator (a couple of minutes).
test-fast: setup
	bash scripts/test.sh -m "not graph and not slow" ros_ws/src

demo: setup
	bash scripts/demo.sh

clean:
	rm -rf .venv ros_ws/build ros_ws/install ros_ws/log
