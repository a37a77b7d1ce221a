# The two commands of the README: `make demo` and `make test`. Both run the set-up first
# (scripts/setup.sh is idempotent and quick when nothing changed).
.PHONY: demo test setup clean

setup:
	@scripts/setup.sh

demo: setup
	@scripts/demo.sh

test: setup
	@scripts/test.sh

clean:
	rm -rf ros2_ws/build ros2_ws/install ros2_ws/log out
