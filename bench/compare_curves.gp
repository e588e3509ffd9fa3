# Error against points drawn of two octocosm-bench-render runs on the same
# snapshot and views (their render_bench.csv files), e.g. two builds' inner
# nodes: PSNR and SSIM of each view's rows of one mode ("clusters" unless
# given), points on a log axis. One file twice, with two modes, compares two
# levels of detail of one run (e.g. clusters and clusters-cut). VIEWS, the
# views to plot (and name in the key), all three unless given.
#   gnuplot -c bench/compare_curves.gp BEFORE.csv "before" AFTER.csv "after" OUT.png [BEFORE_MODE [AFTER_MODE [VIEWS]]]
before = ARG1; before_title = ARG2; after = ARG3; after_title = ARG4
before_mode = ARGC >= 6 ? ARG6 : 'clusters'
after_mode = ARGC >= 7 ? ARG7 : 'clusters'
views = ARGC >= 8 ? ARG8 : 'overview mid deep'
set terminal pngcairo size 1400,560 font ',11'
set output ARG5
set datafile separator ','
set logscale x
set grid
set key top left font ",9"
set multiplot layout 1,2 title 'octocosm: level of detail against the reference, '.before_title.' and '.after_title
set xlabel 'points drawn'
set ylabel 'PSNR (dB)'
set arrow from graph 0, first 40 to graph 1, first 40 nohead dt 2
plot for [i=1:words(views)] before using (strcol(1) eq word(views, i) && strcol(2) eq before_mode ? $5 : 1/0):10 \
       with linespoints pt 4 ps 1.2 dt 2 lc i title word(views, i).', '.before_title, \
     for [i=1:words(views)] after using (strcol(1) eq word(views, i) && strcol(2) eq after_mode ? $5 : 1/0):10 \
       with linespoints pt 7 ps 1.2 lc i title word(views, i).', '.after_title
unset arrow
set ylabel 'SSIM'
set arrow from graph 0, first 0.98 to graph 1, first 0.98 nohead dt 2
plot for [i=1:words(views)] before using (strcol(1) eq word(views, i) && strcol(2) eq before_mode ? $5 : 1/0):11 \
       with linespoints pt 4 ps 1.2 dt 2 lc i title word(views, i).', '.before_title, \
     for [i=1:words(views)] after using (strcol(1) eq word(views, i) && strcol(2) eq after_mode ? $5 : 1/0):11 \
       with linespoints pt 7 ps 1.2 lc i title word(views, i).', '.after_title
unset multiplot
