# gnuplot script of bench/plot.sh, which writes the data files and the plot commands (the file named
# by `series`) and passes out_points, the picture to make.
load series

set terminal pngcairo size 1400,560 enhanced font "DejaVu Sans,11"
set grid xtics ytics mytics lc rgb "#dddddd"
set key top right box opaque samplen 3

# ---- (a) exact 10-NN queries/s against dimension -------------------------------------------------------
set output out_points
set multiplot layout 1,2 title "kdspace-bench: exact 10-NN, 1 thread, queries/s (log) against dimension (1e5 or 1e6 points: see the axis)" font ",13"
set logscale x 2
set xrange [2.4:170]
set logscale y 10
set format y "10^{%L}"
set bmargin 5
set xlabel "dimension" offset 0,-1
set ylabel "queries / s"
eval points_xtics
set title "uniform workloads"
eval plot_points_uniform
set title "clustered workloads (Gaussian blobs)"
eval plot_points_clustered
unset multiplot
set output
