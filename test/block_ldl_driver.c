/* Drives helireach_ros/core/ocp/block_ldl.c through MA27's interface as IPOPT does, for its sanitizer build
 * (test_block_ldl.py compiles both with -fsanitize=address,undefined). Reads matrices from standard input, each as
 * "n nz pivot_tolerance", nz lines "i j value" (1-based, one triangle), then n right-hand-side values; for each it
 * analyses, factorizes (growing the workspace when asked, as IPOPT does), factorizes again in the same workspace
 * (a later iteration of the same solve) and solves, and prints "flag negative" and the solution on one line, or
 * "error <info(1)>". */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

void ma27id_(int *icntl, double *cntl);
void ma27ad_(const int *n, const int *nz, const int *irn, const int *icn, int *iw, const int *liw, int *ikeep,
             int *iw1, int *nsteps, const int *iflag, int *icntl, const double *cntl, int *info, double *ops);
void ma27bd_(const int *n, const int *nz, const int *irn, const int *icn, double *a, const int *la, int *iw,
             const int *liw, const int *ikeep, const int *nsteps, int *maxfrt, int *iw1, const int *icntl,
             const double *cntl, int *info);
void ma27cd_(const int *n, const double *a, const int *la, const int *iw, const int *liw, double *w,
             const int *maxfrt, double *rhs, const int *iw1, const int *nsteps, const int *icntl, int *info);

static int factorize(int n, int nz, const int *irn, const int *icn, const double *values, const int *ikeep,
                     int nsteps, int *iw1, int *icntl, const double *cntl, int *info, double **a, int *la, int **iw,
                     int *liw, int *maxfrt) {
    for (int attempt = 0; attempt < 4; attempt++) {
        if (!*a) { *a = calloc(*la, sizeof(double)); *iw = calloc(*liw, sizeof(int)); }
        memcpy(*a, values, nz * sizeof(double));
        ma27bd_(&n, &nz, irn, icn, *a, la, *iw, liw, ikeep, &nsteps, maxfrt, iw1, icntl, cntl, info);
        if (info[0] != -3 && info[0] != -4) return info[0];
        if (info[0] == -3) *liw = info[1]; else *la = info[1];
        free(*a); free(*iw); *a = NULL; *iw = NULL;
    }
    return info[0];
}

int main(void) {
    int n, nz;
    double tolerance;
    while (scanf("%d %d %lf", &n, &nz, &tolerance) == 3) {
        int *irn = malloc((nz + 1) * sizeof(int)), *icn = malloc((nz + 1) * sizeof(int));
        double *values = malloc((nz + 1) * sizeof(double)), *rhs = malloc((n + 1) * sizeof(double));
        for (int t = 0; t < nz; t++)
            if (scanf("%d %d %lf", &irn[t], &icn[t], &values[t]) != 3) return 2;
        for (int i = 0; i < n; i++)
            if (scanf("%lf", &rhs[i]) != 1) return 2;
        int icntl[30], info[20], nsteps = 0, iflag = 0, liw = 1, iw_unused = 0, maxfrt = 0;
        double cntl[5], ops = 0.0;
        ma27id_(icntl, cntl);
        cntl[0] = tolerance;
        int *ikeep = calloc(3 * n, sizeof(int)), *iw1 = calloc(2 * n, sizeof(int)); /* MA27's sizes, as IPOPT allocates */
        ma27ad_(&n, &nz, irn, icn, &iw_unused, &liw, ikeep, iw1, &nsteps, &iflag, icntl, cntl, info, &ops);
        if (info[0] < 0) {
            printf("error %d\n", info[0]);
        } else {
            int la = info[4];
            liw = info[5];
            double *a = NULL;
            int *iw = NULL;
            int flag = factorize(n, nz, irn, icn, values, ikeep, nsteps, iw1, icntl, cntl, info, &a, &la, &iw, &liw,
                                 &maxfrt);
            if (flag >= 0) flag = factorize(n, nz, irn, icn, values, ikeep, nsteps, iw1, icntl, cntl, info, &a, &la,
                                            &iw, &liw, &maxfrt);
            if (flag < 0) {
                printf("error %d\n", flag);
            } else {
                int negative = info[14];
                double *work = calloc(maxfrt + 1, sizeof(double));
                ma27cd_(&n, a, &la, iw, &liw, work, &maxfrt, rhs, iw1, &nsteps, icntl, info);
                printf("%d %d", flag, negative);
                for (int i = 0; i < n; i++) printf(" %.17g", rhs[i]);
                printf("\n");
                free(work);
            }
            free(a); free(iw);
        }
        free(ikeep); free(iw1); free(irn); free(icn); free(values); free(rhs);
    }
    return 0;
}
