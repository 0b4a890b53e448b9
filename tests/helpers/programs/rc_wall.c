/* External test program in C: the same one-node RC wall as rc_wall.py.
 * Reads params.txt ("name = value" lines: R, C, T0) and forcing.csv
 * ("time,temp_air_out" header, then rows), writes out.csv (time,T,q).
 * Build: gcc -O2 -o rc_wall rc_wall.c -lm
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

int main(void) {
    double R = NAN, C = NAN, T = NAN, value;
    char key[64];
    FILE *f = fopen("params.txt", "r");
    if (!f) { fprintf(stderr, "rc_wall: cannot open params.txt\n"); return 2; }
    while (fscanf(f, " %63[^= ] = %lf", key, &value) == 2) {
        if (!strcmp(key, "R")) R = value;
        else if (!strcmp(key, "C")) C = value;
        else if (!strcmp(key, "T0")) T = value;
    }
    fclose(f);
    if (isnan(R) || isnan(C) || isnan(T)) { fprintf(stderr, "rc_wall: R, C or T0 missing\n"); return 2; }
    FILE *in = fopen("forcing.csv", "r"), *out = fopen("out.csv", "w");
    if (!in || !out) { fprintf(stderr, "rc_wall: cannot open forcing.csv or out.csv\n"); return 2; }
    char header[256];
    if (!fgets(header, sizeof header, in)) { fprintf(stderr, "rc_wall: empty forcing.csv\n"); return 2; }
    double t, u, t_prev = 0.0, u_prev = 0.0;
    const double tau = R * C;
    int first = 1;
    fprintf(out, "time,T,q\n");
    while (fscanf(in, " %lf,%lf", &t, &u) == 2) {
        if (!first) {
            const double h = t - t_prev, b = (u - u_prev) / h;
            T = u - b * tau + (T - u_prev + b * tau) * exp(-h / tau);
        }
        fprintf(out, "%.17g,%.17g,%.17g\n", t, T, (u - T) / R);
        t_prev = t; u_prev = u; first = 0;
    }
    fclose(in);
    fclose(out);
    return 0;
}
