# The three commands of cap-ros. Each one sets up what it needs first (fast when nothing changed).
.PHONY: setup test demo clean

setup:
	bash scripts/setup.sh

test: setup
	bash scripts/test.sh

demo: setup
	bash scripts/demo.sh

clean:
	rm -rf .venv ros_ws/build ros_ws/install ros_ws/log
