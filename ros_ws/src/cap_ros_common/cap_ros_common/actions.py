"""What every action server of the graph shares."""

# How long a server keeps a finished goal's result [s of the server's clock] for a client that asks for it late.
# Every goal kept is listed in each status message the server publishes, and every client of the action takes and
# deserializes those lists in Python. At rclpy's default (900 s) the simulator's trajectory and gripper servers
# (on the wall clock) kept thousands of goals in a long benchmark run, and each job slowed from 9x to 3x real time
# over its first 250 episodes. The graph's clients ask for the result as soon as a goal is accepted (the result
# then waits for them, however long the goal runs); 10 s still serves a client that asks a little late.
RESULT_TIMEOUT_S = 10

__all__ = ['RESULT_TIMEOUT_S']
