/* fxload_plot.h — fxload's --plot: the per-second rows of a finished run drawn by gnuplot into
 * FILE.svg or FILE.png (fxload_plot.c says what each panel shows). */
#ifndef FXLOAD_PLOT_H
#define FXLOAD_PLOT_H

struct ld;

/* Returns 0, or -1 after saying why on stderr (gnuplot missing or failing). */
int ld_plot(const struct ld *ld);

#endif
