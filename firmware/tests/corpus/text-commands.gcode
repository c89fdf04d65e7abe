M117 Hello ; world
M118 E1 é
M118
