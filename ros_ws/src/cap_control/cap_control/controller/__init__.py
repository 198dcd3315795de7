"""Generated reactive controllers run at a fixed rate: plan (what a run may do: its checks and limits; the loop
plans nothing), executor (the control loop over the plant and controller ports) and node (the RunController
action)."""
