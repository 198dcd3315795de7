"""Facts of the whiteboard domain, pure Python: the board and its ink image (board.py), the drawing tool with its
marker and eraser (tool.py), and the objects that stand on the board (objects.py)."""
