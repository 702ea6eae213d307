#!/usr/bin/python3
"""check_cell_processes.py ROWS COLS MAX: sim.launch's guard of one process per cell.

Prints ROWS * COLS (the parameter's value) when the bed has at most MAX cells; otherwise says
why on stderr and exits 1, which stops roslaunch before any cell starts: one process per cell
(use_nodelets:=false) costs a process, its threads and its TCP topics per cell, and a machine
that cannot carry them starves the cells' watchdogs (doc/airbag_node.md).
"""
import sys


def main(argv):
    try:
        rows, cols, limit = (int(a) for a in argv)
    except ValueError:
        print("check_cell_processes.py: usage: ROWS COLS MAX (integers)", file=sys.stderr)
        return 2
    cells = rows * cols
    if cells > limit:
        print("sim.launch: use_nodelets:=false runs one process per cell, and %d x %d = %d cells exceed "
              "max_cell_processes (%d), the most this mode is set to carry. Use use_nodelets:=true (the default: "
              "the whole bed in one nodelet manager), a smaller bed, or max_cell_processes:=%d on a machine "
              "that carries it (doc/airbag_node.md)." % (rows, cols, cells, limit, cells), file=sys.stderr)
        return 1
    print(cells)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
