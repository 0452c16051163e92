#!/usr/bin/env python3
"""Write the loose starting layer of the benchmark as a LAMMPS data file (atom_style sphere).

    python3 make_layer.py N FILE [SEED]

Lengths in mean grain diameters d. The periodic width is W = round(200 sqrt(N / 10000)) d, as in
`gouge bench`. Each wall is one row of W grains 1 d apart (type 2 at the bottom, type 3 at the
top); the other N - 2 W grains (type 1) sit on a loose square lattice (pitch 1.25 d, small
random offsets, no overlaps) between them. Diameters are uniform in [0.8, 1.2] d. The file holds
exactly N atoms; compaction under the normal stress brings the layer to about W / 4 thick.
"""
import math
import random
import sys


def layer(n_atoms: int, seed: int):
    rng = random.Random(seed)
    width = round(200.0 * math.sqrt(n_atoms / 1.0e4))
    n_wall = int(width)
    n_free = n_atoms - 2 * n_wall
    pitch = 1.25
    per_row = int(width // pitch)
    rows = -(-n_free // per_row)
    atoms = [(2, rng.uniform(0.8, 1.2), i + 0.5, 0.0) for i in range(n_wall)]
    for k in range(n_free):
        r, c = divmod(k, per_row)
        atoms.append((1, rng.uniform(0.8, 1.2),
                      (c + 0.5) * width / per_row + rng.uniform(-0.05, 0.05),
                      1.3 + r * pitch + rng.uniform(-0.05, 0.05)))
    top = 1.3 + rows * pitch + 0.1
    atoms += [(3, rng.uniform(0.8, 1.2), i + 0.5, top) for i in range(n_wall)]
    return width, top, atoms


def main(argv):
    n_atoms, path = int(argv[1]), argv[2]
    seed = int(argv[3]) if len(argv) > 3 else 2024
    width, top, atoms = layer(n_atoms, seed)
    with open(path, "w") as f:
        f.write(f"gouge benchmark layer: {len(atoms)} discs, width {width} d, seed {seed}\n\n")
        f.write(f"{len(atoms)} atoms\n3 atom types\n\n")
        f.write(f"0 {width:.6f} xlo xhi\n-1.0 {top + 2.0:.6f} ylo yhi\n-0.5 0.5 zlo zhi\n\n")
        f.write("Atoms # sphere\n\n")
        for i, (kind, diameter, x, y) in enumerate(atoms, 1):
            f.write(f"{i} {kind} {diameter:.6f} 1.0 {x:.6f} {y:.6f} 0.0\n")
    print(f"N={len(atoms)} width={width} top={top:.3f}")


if __name__ == "__main__":
    main(sys.argv)
