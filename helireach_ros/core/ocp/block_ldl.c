/* A block LDL^T for IPOPT's KKT systems, behind IPOPT's MA27 interface (helireach_ros.core.ocp.block_ldl builds it and
 * hands it to IPOPT as `linear_solver ma27`, `hsllib <this library>`; IPOPT 3.14 loads MA27's four routines
 * MA27ID/AD/BD/CD from any library). It replaces MUMPS for the landing NLPs: measured 0.46-0.50x of MUMPS's IPOPT
 * time on flyable plans, with about the same iterations and the same statuses and replay verdicts (docs/decisions/block-ldl.md).
 *
 * IPOPT's augmented system K = [H J^T; J -dc I] has a zero diagonal at every multiplier until IPOPT regularises,
 * so no 1x1 pivot order works for it. The analysis pairs each multiplier with a primal variable of its constraint
 * (a maximum bipartite matching that prefers the least-connected variable, e.g. an inequality's own slack); each
 * pair is one 2x2 pivot [h a; a 0], nonsingular whenever the Jacobian entry a is not zero. The analysis (MA27AD)
 * sees no values, so the first factorization of each solve checks its pairs against the values and pairs again by
 * value where an entry is small relative to its multiplier's largest (PAIR_TAU, PAIR_KEEP below), ordering anew;
 * the new pairs serve the rest of the solve. (A structural pair on a near-zero entry, 2.9e-11 seen, gave element
 * growth to 1e20 and wrong inertia.)
 * Blocks (pairs and the unpaired primal variables, padded with a unit slot) are ordered by minimum degree, and the
 * factorization is the up-looking LDL^T of T. Davis's LDL with 2x2 blocks for scalars. Inertia comes from the
 * signs of the 2x2 pivots. There is no threshold pivoting: a pivot block that the Schur updates make small is
 * perturbed and reported as rank deficient (MA27's warning 3), so IPOPT regularises and factorizes again.
 *
 * IPOPT's pivot tolerance (CNTL(1), its option ma27_pivtol, raised towards ma27_pivtolmax when IPOPT wants a more
 * accurate factorization) scales the relative size below which a pivot counts as singular: 1e-12 for a 2x2 pivot at
 * IPOPT's default 1e-8, 1e-8 at its largest 1e-4, so that raising it makes more nearly singular pivots perturbed and
 * reported (IPOPT regularises), not a no-op.
 *
 * Errors, in INFO(1): -1 an order n below 3 or an index outside [1, n] (this also catches a caller with 64-bit
 * indices, whose high words read as index 0: the routines take IPOPT's default 32-bit ipfint), -3/-4 workspace too
 * small (INFO(2) says how much), -7 out of memory. IPOPT treats any of them but -3/-4 as a fatal solver error.
 *
 * Debug switches (environment): BLOCK_LDL_VERBOSE, BLOCK_LDL_TIMES (a summary at exit), BLOCK_LDL_DUMPDIR (the
 * first 400 KKT matrices as text, for bench/linear_solver_compare.py --check-inertia), BLOCK_LDL_QUIET_PERTURB,
 * BLOCK_LDL_STRUCTURAL_PAIRS (pairs chosen by the structure alone, for comparison).
 */
#include <math.h>
#include <pthread.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
/* Timing counters (BLOCK_LDL_TIMES) are shared by every thread that solves: updated under a lock, only when asked. */
static double t_a, t_b, t_c; static long n_a, n_b, n_c, repairs;
static pthread_mutex_t timing_lock = PTHREAD_MUTEX_INITIALIZER;
static double now(void) { struct timespec ts; clock_gettime(CLOCK_MONOTONIC, &ts); return ts.tv_sec + 1e-9 * ts.tv_nsec; }
static int timing(void) { static int enabled = -1; if (enabled < 0) enabled = getenv("BLOCK_LDL_TIMES") != NULL; return enabled; }
__attribute__((destructor)) static void report(void) { if (timing()) fprintf(stderr, "block_ldl times: analyse %ld x %.1f us, factor %ld x %.1f us (%ld paired anew by values), solve %ld x %.1f us\n", n_a, 1e6 * t_a / (n_a ? n_a : 1), n_b, 1e6 * t_b / (n_b ? n_b : 1), __atomic_load_n(&repairs, __ATOMIC_RELAXED), n_c, 1e6 * t_c / (n_c ? n_c : 1)); }

typedef int fint; /* IPOPT's ipfint without IPOPT_INT64: a 64-bit caller is refused by the index check (header) */
_Static_assert(sizeof(fint) == 4, "MA27's interface takes 32-bit integers");
enum { OUT_OF_MEMORY = -7 };
#define MAGIC 0x4c444c32
#define HEADER 8

static inline void mul(const double *a, const double *b, double *c) { /* c = a b */
    c[0] = a[0] * b[0] + a[1] * b[2];
    c[1] = a[0] * b[1] + a[1] * b[3];
    c[2] = a[2] * b[0] + a[3] * b[2];
    c[3] = a[2] * b[1] + a[3] * b[3];
}
static inline void mul_tn(const double *a, const double *b, double *c) { /* c = a^T b */
    c[0] = a[0] * b[0] + a[2] * b[2];
    c[1] = a[0] * b[1] + a[2] * b[3];
    c[2] = a[1] * b[0] + a[3] * b[2];
    c[3] = a[1] * b[1] + a[3] * b[3];
}

#define DEFAULT_PIVOT_TOLERANCE 1e-8 /* IPOPT's ma27_pivtol default, the tolerance the thresholds were measured at */
static void ma27id_impl(fint *icntl, double *cntl) {
    memset(icntl, 0, 30 * sizeof(fint));
    memset(cntl, 0, 5 * sizeof(double));
    cntl[0] = DEFAULT_PIVOT_TOLERANCE;
}

/* How much stricter than at the default tolerance the singular-pivot test is: 1 at or below IPOPT's default, up to
 * 1e4 at its largest tolerance 1e-4 (a NaN or negative tolerance counts as the default). */
static double pivot_strictness(const double *cntl) {
    double ratio = cntl ? cntl[0] / DEFAULT_PIVOT_TOLERANCE : 1.0;
    return ratio > 1.0 ? fmin(ratio, 1e4) : 1.0;
}

static int analysis_stamp = 0x5eed;
enum { IKEEP_MIN_N = 3 }; /* the smallest n whose 3n-long ikeep has room for n pairs and 5 header entries */
static int verbose(void) { return getenv("BLOCK_LDL_VERBOSE") != NULL; }

/* ---------------------------------------------------------------- analysis */
/* Analyses by structure: IPOPT analyses again at every solve, of the same matrix structure. An entry keeps the
 * structure itself (irn, icn), so a hash collision is a miss, never another matrix's pairs. */
#define CACHE_SLOTS 16
typedef struct { int n, nz; uint64_t hash; int *code; fint *irn, *icn; int b, lnz, m0; long used; } analysis;
static analysis cache[CACHE_SLOTS];
static long cache_clock = 0;
static pthread_mutex_t cache_lock = PTHREAD_MUTEX_INITIALIZER;

static uint64_t structure_hash(int nz, const fint *irn, const fint *icn) {
    uint64_t h = 1469598103934665603ULL;
    for (int t = 0; t < nz; t++) {
        h = (h ^ (uint32_t)irn[t]) * 1099511628211ULL;
        h = (h ^ (uint32_t)icn[t]) * 1099511628211ULL;
    }
    return h;
}

static int cache_get(int n, int nz, uint64_t hash, const fint *irn, const fint *icn, fint *ikeep) {
    int found = 0;
    pthread_mutex_lock(&cache_lock);
    for (int s = 0; s < CACHE_SLOTS; s++) {
        analysis *e = &cache[s];
        if (e->code && e->n == n && e->nz == nz && e->hash == hash && !memcmp(e->irn, irn, nz * sizeof(fint)) &&
            !memcmp(e->icn, icn, nz * sizeof(fint))) {
            memcpy(ikeep, e->code, n * sizeof(fint));
            ikeep[n] = MAGIC; ikeep[n + 1] = e->b; ikeep[n + 2] = e->lnz; ikeep[n + 3] = e->m0;
            e->used = ++cache_clock;
            found = 1;
            break;
        }
    }
    pthread_mutex_unlock(&cache_lock);
    return found;
}

static void cache_put(int n, int nz, uint64_t hash, const fint *irn, const fint *icn, const fint *ikeep) {
    int *code = malloc(n * sizeof(int));
    fint *rows = malloc(nz * sizeof(fint)), *cols = malloc(nz * sizeof(fint));
    if (!code || !rows || !cols) { free(code); free(rows); free(cols); return; } /* no cache entry: analyse again */
    memcpy(code, ikeep, n * sizeof(int));
    memcpy(rows, irn, nz * sizeof(fint));
    memcpy(cols, icn, nz * sizeof(fint));
    pthread_mutex_lock(&cache_lock);
    int victim = 0;
    for (int s = 0; s < CACHE_SLOTS; s++) {
        if (!cache[s].code) { victim = s; break; }
        if (cache[s].used < cache[victim].used) victim = s;
    }
    analysis *e = &cache[victim];
    free(e->code); free(e->irn); free(e->icn);
    e->code = code; e->irn = rows; e->icn = cols;
    e->n = n; e->nz = nz; e->hash = hash;
    e->b = ikeep[n + 1]; e->lnz = ikeep[n + 2]; e->m0 = ikeep[n + 3];
    e->used = ++cache_clock;
    pthread_mutex_unlock(&cache_lock);
}

typedef struct {
    int n, nz, m0, unmatched;
    int *adjp, *adji; /* deduplicated symmetric adjacency of nodes, no diagonal */
    double *adjx;     /* |a| of each adjacency entry (values known), or NULL (structure only) */
    int *mate;        /* multiplier -> primal and primal -> multiplier, -1 if none */
    double tau;       /* with values: a pair's |a| must be at least tau times its multiplier's largest entry */
} graph;

/* Builds g's adjacency; 0, or OUT_OF_MEMORY with nothing allocated. */
static int build_graph(graph *g, const fint *irn, const fint *icn, const double *a) {
    int n = g->n, nz = g->nz;
    int *count = calloc(n + 1, sizeof(int));
    if (!count) return OUT_OF_MEMORY;
    for (int t = 0; t < nz; t++) {
        int i = irn[t] - 1, j = icn[t] - 1;
        if (i != j) { count[i + 1]++; count[j + 1]++; }
    }
    for (int i = 0; i < n; i++) count[i + 1] += count[i];
    size_t entries = count[n] > 0 ? count[n] : 1;
    int *adj = malloc(entries * sizeof(int)), *cursor = malloc(n * sizeof(int));
    int *mark = malloc(n * sizeof(int)), *where = malloc(n * sizeof(int)), *p = malloc((n + 1) * sizeof(int));
    double *val = a ? malloc(entries * sizeof(double)) : NULL;
    if (!adj || !cursor || !mark || !where || !p || (a && !val)) {
        free(count); free(adj); free(cursor); free(mark); free(where); free(p); free(val);
        return OUT_OF_MEMORY;
    }
    memcpy(cursor, count, n * sizeof(int));
    for (int t = 0; t < nz; t++) {
        int i = irn[t] - 1, j = icn[t] - 1;
        if (i != j) {
            if (val) { val[cursor[i]] = fabs(a[t]); val[cursor[j]] = fabs(a[t]); }
            adj[cursor[i]++] = j; adj[cursor[j]++] = i;
        }
    }
    /* deduplicate in place (a repeated entry keeps its largest magnitude) */
    for (int i = 0; i < n; i++) mark[i] = -1;
    int out = 0;
    for (int i = 0; i < n; i++) {
        p[i] = out;
        for (int q = count[i]; q < count[i + 1]; q++) {
            int j = adj[q];
            if (mark[j] != i) {
                mark[j] = i; where[j] = out;
                if (val) val[out] = val[q];
                adj[out++] = j;
            } else if (val && val[q] > val[where[j]]) {
                val[where[j]] = val[q];
            }
        }
    }
    p[n] = out;
    free(count); free(cursor); free(mark); free(where);
    g->adjp = p;
    g->adji = adj;
    g->adjx = val;
    return 0;
}

/* Whether the edge (multiplier j, primal at adjacency position q) may be a 2x2 pivot: structure only, or an entry
 * of at least tau times the multiplier's largest entry to a primal node (rowmax). */
static inline int strong(const graph *g, int q, const double *rowmax, int j) {
    return !g->adjx || g->adjx[q] >= g->tau * rowmax[j];
}

static int augment(const graph *g, int j, int *visited, int stamp, const double *rowmax, int strict) {
    /* Kuhn's augmenting path from multiplier j (strict: over strong edges only) */
    for (int q = g->adjp[j]; q < g->adjp[j + 1]; q++) {
        int i = g->adji[q];
        if (i >= g->m0 || visited[i] == stamp || (strict && !strong(g, q, rowmax, j))) continue;
        visited[i] = stamp;
        if (g->mate[i] < 0 || augment(g, g->mate[i], visited, stamp, rowmax, strict)) {
            g->mate[i] = j;
            g->mate[j] = i;
            return 1;
        }
    }
    return 0;
}

/* Pairs multipliers with primal variables into g->mate; 0, or OUT_OF_MEMORY (g->mate may then be set, freed by the
 * caller with the graph). */
static int match(graph *g) {
    int n = g->n, m0 = g->m0;
    g->mate = malloc(n * sizeof(int));
    double *rowmax = calloc(n, sizeof(double));
    int *visited = calloc(n, sizeof(int));
    if (!g->mate || !rowmax || !visited) { free(rowmax); free(visited); return OUT_OF_MEMORY; }
    for (int i = 0; i < n; i++) g->mate[i] = -1;
    if (g->adjx)
        for (int j = m0; j < n; j++)
            for (int q = g->adjp[j]; q < g->adjp[j + 1]; q++)
                if (g->adji[q] < m0 && g->adjx[q] > rowmax[j]) rowmax[j] = g->adjx[q];
    for (int j = m0; j < n; j++) { /* greedy: the free strong primal neighbour with the fewest neighbours */
        int best = -1;
        for (int q = g->adjp[j]; q < g->adjp[j + 1]; q++) {
            int i = g->adji[q];
            if (i >= m0 || g->mate[i] >= 0 || !strong(g, q, rowmax, j)) continue;
            if (best < 0 || g->adjp[i + 1] - g->adjp[i] < g->adjp[best + 1] - g->adjp[best]) best = i;
        }
        if (best >= 0) { g->mate[best] = j; g->mate[j] = best; }
    }
    int unmatched = 0, stamp = 0;
    for (int strict = 1; strict >= 0; strict--) { /* strong edges first; then any edge, so every multiplier pairs */
        unmatched = 0;
        for (int j = m0; j < n; j++) {
            if (g->mate[j] >= 0) continue;
            if (!augment(g, j, visited, ++stamp, rowmax, strict)) unmatched++;
        }
        if (!g->adjx) break;
    }
    free(visited); free(rowmax);
    g->unmatched = unmatched;
    return 0;
}

static int popcount_row(const uint64_t *row, int words) {
    int c = 0;
    for (int w = 0; w < words; w++) c += __builtin_popcountll(row[w]);
    return c;
}

/* Minimum-degree order of the block graph (explicit elimination graph in bitsets: the graphs here are small). */
static int min_degree(int b, const int *bp, const int *bi, int *order) {
    int words = (b + 63) / 64;
    uint64_t *adj = calloc((size_t)b * words > 0 ? (size_t)b * words : 1, sizeof(uint64_t));
    int *deg = malloc((b > 0 ? b : 1) * sizeof(int));
    char *done = calloc(b > 0 ? b : 1, 1);
    if (!adj || !deg || !done) { free(adj); free(deg); free(done); return OUT_OF_MEMORY; }
    for (int u = 0; u < b; u++)
        for (int q = bp[u]; q < bp[u + 1]; q++) adj[(size_t)u * words + bi[q] / 64] |= 1ULL << (bi[q] % 64);
    for (int u = 0; u < b; u++) deg[u] = popcount_row(adj + (size_t)u * words, words);
    for (int k = 0; k < b; k++) {
        int v = -1;
        for (int u = 0; u < b; u++)
            if (!done[u] && (v < 0 || deg[u] < deg[v])) v = u;
        order[k] = v;
        done[v] = 1;
        uint64_t *rv = adj + (size_t)v * words;
        for (int w = 0; w < words; w++) {
            uint64_t bits = rv[w];
            while (bits) {
                int u = w * 64 + __builtin_ctzll(bits);
                bits &= bits - 1;
                uint64_t *ru = adj + (size_t)u * words;
                for (int x = 0; x < words; x++) ru[x] |= rv[x];
                ru[u / 64] &= ~(1ULL << (u % 64));
                ru[v / 64] &= ~(1ULL << (v % 64));
                deg[u] = popcount_row(ru, words);
            }
        }
        memset(rv, 0, words * sizeof(uint64_t));
    }
    free(adj); free(deg); free(done);
    return 0;
}

/* Entries of the upper block triangle by column block: row block, where in the 2x2 block, value. */
/* cursor: b integers of workspace. */
static void block_columns(int nz, int b, const fint *irn, const fint *icn, const double *a, const fint *code,
                          fint *cp, fint *ci, fint *cs, double *cx, fint *pos, fint *cursor) {
    memset(cp, 0, (b + 1) * sizeof(fint));
    for (int t = 0; t < nz; t++) {
        int bi = code[irn[t] - 1] >> 1, bj = code[icn[t] - 1] >> 1;
        cp[(bi > bj ? bi : bj) + 1]++;
    }
    for (int k = 0; k < b; k++) cp[k + 1] += cp[k];
    memcpy(cursor, cp, b * sizeof(fint));
    for (int t = 0; t < nz; t++) {
        int ci_ = code[irn[t] - 1], cj = code[icn[t] - 1];
        int bi = ci_ >> 1, bj = cj >> 1, si = ci_ & 1, sj = cj & 1;
        int slot;
        int col, row;
        if (bi == bj) { col = row = bi; slot = si == sj ? 3 * si : 4; }
        else if (bi < bj) { row = bi; col = bj; slot = 2 * si + sj; }
        else { row = bj; col = bi; slot = 2 * sj + si; }
        int p = cursor[col]++;
        ci[p] = row;
        if (cs) cs[p] = slot;
        if (cx) cx[p] = a[t];
        if (pos) pos[t] = p;
    }
}

static int block_symbolic(int b, const fint *cp, const fint *ci, fint *lp, fint *parent, fint *lnz, fint *flag) {
    for (int k = 0; k < b; k++) {
        parent[k] = -1; flag[k] = k; lnz[k] = 0;
        for (int p = cp[k]; p < cp[k + 1]; p++) {
            int i = ci[p];
            for (; flag[i] != k; i = parent[i]) {
                if (parent[i] == -1) parent[i] = k;
                lnz[i]++;
                flag[i] = k;
            }
        }
    }
    lp[0] = 0;
    for (int k = 0; k < b; k++) lp[k + 1] = lp[k] + lnz[k];
    return lp[b];
}

static int reals_needed(int nz, int b, int lnz) { return nz + 4 * b + 4 * lnz + 4 * b + nz; }
static int ints_needed(int n, int nz, int b, int lnz) {
    return HEADER + n + (b + 1) + lnz + 4 * b + (b + 1) + nz + nz + nz;
}

/* The analysis: pairs, block order and L's block count into code[0..n) (2 * block position + slot); with values
 * (a != NULL) a pair needs an entry of at least tau times its multiplier's largest one where any pairing allows.
 * Returns 0, or OUT_OF_MEMORY (code unspecified). */
static int analyse(int n, int nz, const fint *irn, const fint *icn, const double *a, double tau, fint *code,
                   int *b_out, int *lnz_out, int *m0_out, int *unmatched_out, double *flops_out) {
    graph g = {n, nz, n, 0, NULL, NULL, NULL, NULL, tau};
    int status = build_graph(&g, irn, icn, a);
    if (status) return status;
    /* the trailing independent block: every node from m0 on has no neighbour after it */
    int m0 = n;
    while (m0 > 0) {
        int i = m0 - 1, maxnb = -1;
        for (int q = g.adjp[i]; q < g.adjp[i + 1]; q++) if (g.adji[q] > maxnb) maxnb = g.adji[q];
        if (maxnb > i) break;
        m0--;
    }
    if (m0 == 0) m0 = n; /* a diagonal matrix: no multipliers */
    g.m0 = m0;
    int *block_of = NULL, *slot_of = NULL, *bcount = NULL, *badj = NULL, *bcur = NULL, *order = NULL, *position = NULL;
    fint *cp = NULL, *ci = NULL, *lp = NULL, *parent = NULL, *lnzc = NULL, *flag = NULL;
    status = match(&g);
    if (status) goto done;
    block_of = malloc(n * sizeof(int));
    slot_of = malloc(n * sizeof(int));
    if (!block_of || !slot_of) { status = OUT_OF_MEMORY; goto done; }
    /* blocks: a pair (primal slot 0, multiplier slot 1) or a single node (slot 0) padded with a unit slot 1 */
    int b = 0;
    for (int i = 0; i < n; i++) {
        if (i < m0) {
            block_of[i] = b; slot_of[i] = 0;
            if (g.mate[i] >= 0) { block_of[g.mate[i]] = b; slot_of[g.mate[i]] = 1; }
            b++;
        } else if (g.mate[i] < 0) {
            block_of[i] = b++; slot_of[i] = 0;
        }
    }
    /* block graph */
    bcount = calloc(b + 1, sizeof(int));
    if (!bcount) { status = OUT_OF_MEMORY; goto done; }
    for (int i = 0; i < n; i++)
        for (int q = g.adjp[i]; q < g.adjp[i + 1]; q++)
            if (block_of[g.adji[q]] != block_of[i]) bcount[block_of[i] + 1]++;
    for (int k = 0; k < b; k++) bcount[k + 1] += bcount[k];
    badj = malloc((bcount[b] > 0 ? bcount[b] : 1) * sizeof(int));
    bcur = malloc((b > 0 ? b : 1) * sizeof(int));
    order = malloc((b > 0 ? b : 1) * sizeof(int));
    position = malloc((b > 0 ? b : 1) * sizeof(int));
    cp = malloc((b + 1) * sizeof(fint));
    ci = malloc((nz > 0 ? nz : 1) * sizeof(fint));
    lp = malloc((b + 1) * sizeof(fint));
    parent = malloc((b > 0 ? b : 1) * sizeof(fint));
    lnzc = malloc((b > 0 ? b : 1) * sizeof(fint));
    flag = malloc((b > 0 ? b : 1) * sizeof(fint));
    if (!badj || !bcur || !order || !position || !cp || !ci || !lp || !parent || !lnzc || !flag) {
        status = OUT_OF_MEMORY;
        goto done;
    }
    memcpy(bcur, bcount, b * sizeof(int));
    for (int i = 0; i < n; i++)
        for (int q = g.adjp[i]; q < g.adjp[i + 1]; q++)
            if (block_of[g.adji[q]] != block_of[i]) badj[bcur[block_of[i]]++] = block_of[g.adji[q]];
    if ((status = min_degree(b, bcount, badj, order))) goto done;
    for (int k = 0; k < b; k++) position[order[k]] = k;
    for (int i = 0; i < n; i++) code[i] = 2 * position[block_of[i]] + slot_of[i];
    block_columns(nz, b, irn, icn, NULL, code, cp, ci, NULL, NULL, NULL, flag); /* flag: free until the symbolic */
    int lnz = block_symbolic(b, cp, ci, lp, parent, lnzc, flag);
    double flops = 0;
    for (int k = 0; k < b; k++) flops += 8.0 * lnzc[k] * lnzc[k];
    *b_out = b; *lnz_out = lnz; *m0_out = m0; *unmatched_out = g.unmatched; *flops_out = flops;
done:
    free(cp); free(ci); free(lp); free(parent); free(lnzc); free(flag);
    free(block_of); free(slot_of); free(bcount); free(badj); free(bcur); free(order); free(position);
    free(g.adjp); free(g.adji); free(g.adjx); free(g.mate);
    return status;
}

static void ma27ad_impl(const fint *N, const fint *NZ, const fint *irn, const fint *icn, fint *iw, const fint *liw,
                        fint *ikeep, fint *iw1, fint *nsteps, const fint *iflag, fint *icntl, const double *cntl,
                        fint *info, double *ops) {
    (void)iw; (void)liw; (void)iw1; (void)iflag; (void)icntl; (void)cntl;
    int n = *N, nz = *NZ;
    memset(info, 0, 20 * sizeof(fint));
    /* the analysis keeps its pairs in ikeep[0, n) and five header entries after them: MA27's ikeep holds 3n */
    if (n < IKEEP_MIN_N) { info[0] = -1; info[1] = n; return; }
    for (int t = 0; t < nz; t++)
        if (irn[t] < 1 || irn[t] > n || icn[t] < 1 || icn[t] > n) { info[0] = -1; info[1] = t + 1; return; }
    uint64_t hash = structure_hash(nz, irn, icn);
    /* a fresh stamp for every analysis: a solve starts from the analysis's pairs, never from pairs an earlier solve
     * left in a workspace IPOPT reuses, so a solve's answer does not depend on the solves before it */
    ikeep[n + 4] = __atomic_add_fetch(&analysis_stamp, 1, __ATOMIC_RELAXED);
    if (n >= 8 && cache_get(n, nz, hash, irn, icn, ikeep)) {
        int b = ikeep[n + 1], lnz = ikeep[n + 2];
        *nsteps = 1;
        *ops = 0;
        info[4] = reals_needed(nz, b, 2 * lnz);
        info[5] = ints_needed(n, nz, b, 2 * lnz);
        return;
    }
    int b, lnz, m0, unmatched;
    double flops;
    if (analyse(n, nz, irn, icn, NULL, 0.0, ikeep, &b, &lnz, &m0, &unmatched, &flops)) {
        info[0] = OUT_OF_MEMORY;
        return;
    }
    ikeep[n] = MAGIC; ikeep[n + 1] = b; ikeep[n + 2] = lnz; ikeep[n + 3] = m0;
    *nsteps = 1;
    *ops = flops;
    /* room for a value-based pairing's extra fill (ma27bd asks for more if even that is short) */
    info[4] = reals_needed(nz, b, 2 * lnz);
    info[5] = ints_needed(n, nz, b, 2 * lnz);
    if (n >= 8) cache_put(n, nz, hash, irn, icn, ikeep);
    if (verbose())
        fprintf(stderr, "block_ldl: n %d nz %d primal %d, %d blocks, %d multipliers unpaired, %d L blocks\n", n, nz, m0, b,
                unmatched, lnz);
}

/* ---------------------------------------------------------------- factorization */
/* Pairs by value: the first factorization of a solve pairs again whenever a pair's entry is below PAIR_TAU times its
 * multiplier's largest entry to a primal node (the new pairs need PAIR_TAU where a complete pairing allows); later
 * factorizations of the solve keep their pairs unless one falls below PAIR_KEEP. Re-pairing is a discrete choice, so
 * it is made once per solve where possible: re-pairing within a solve at 1e-4 made a closed loop's touchdown 100x more
 * sensitive to a 1e-7 change of its start (1.3e-3 against 1.3e-5 m/s with MUMPS; 7e-5 with this policy). */
#define PAIR_TAU 1e-2
#define PAIR_KEEP 1e-8

/* 1 if a pair's entry is below keep times its multiplier's largest, 0 if none is, OUT_OF_MEMORY. */
static int weak_pair(int n, int nz, const fint *irn, const fint *icn, const double *a, const fint *code, int b,
                     double keep) {
    double *rowmax = calloc(2 * b + 1, sizeof(double)), *pair = calloc(b + 1, sizeof(double));
    if (!rowmax || !pair) { free(rowmax); free(pair); return OUT_OF_MEMORY; }
    /* a pair's slot-1 node is its multiplier; a block whose slot 1 holds no node is a single primal node */
    for (int t = 0; t < nz; t++) {
        int i = irn[t] - 1, j = icn[t] - 1;
        if (i == j) continue;
        int ci_ = code[i], cj = code[j];
        double v = fabs(a[t]);
        if ((ci_ >> 1) == (cj >> 1)) { if (v > pair[ci_ >> 1]) pair[ci_ >> 1] = v; continue; }
        if ((ci_ & 1) && v > rowmax[ci_]) rowmax[ci_] = v;
        if ((cj & 1) && v > rowmax[cj]) rowmax[cj] = v;
    }
    int weak = 0;
    for (int i = 0; i < n && !weak; i++) {
        int c = code[i];
        if (c & 1) weak = pair[c >> 1] < keep * rowmax[c];
    }
    free(rowmax); free(pair);
    return weak;
}

static void ma27bd_impl(const fint *N, const fint *NZ, const fint *irn, const fint *icn, double *a, const fint *la,
                        fint *iw, const fint *liw, const fint *ikeep, const fint *nsteps, fint *maxfrt, fint *iw1,
                        const fint *icntl, const double *cntl, fint *info) {
    (void)nsteps; (void)iw1; (void)icntl;
    int n = *N, nz = *NZ;
    memset(info, 0, 20 * sizeof(fint));
    if (n < IKEEP_MIN_N || ikeep[n] != MAGIC) { info[0] = -1; return; }
    double strictness = pivot_strictness(cntl);
    fint *hdr = iw, *code = iw + HEADER;
    int stamp = ikeep[n + 4];
    /* the pairs in force: this solve's value-based ones if an earlier factorization made them, else the analysis's */
    int have = hdr[0] == MAGIC && hdr[5] == stamp && hdr[1] == n && hdr[4] == nz;
    const fint *pairs = have ? code : ikeep;
    int b = have ? hdr[2] : ikeep[n + 1], lnz = have ? hdr[3] : ikeep[n + 2];
    fint *fresh = NULL;
    int weak = getenv("BLOCK_LDL_STRUCTURAL_PAIRS") ? 0 : weak_pair(n, nz, irn, icn, a, pairs, b, have ? PAIR_KEEP : PAIR_TAU);
    if (weak == OUT_OF_MEMORY) { info[0] = OUT_OF_MEMORY; return; }
    if (weak) {
        int m0, unmatched;
        double flops;
        fresh = malloc(n * sizeof(fint));
        if (!fresh || analyse(n, nz, irn, icn, a, PAIR_TAU, fresh, &b, &lnz, &m0, &unmatched, &flops)) {
            free(fresh);
            info[0] = OUT_OF_MEMORY;
            return;
        }
    }
    int need_r = reals_needed(nz, b, lnz), need_i = ints_needed(n, nz, b, lnz);
    if (*liw < need_i || *la < need_r) { /* checked before anything is written into iw */
        free(fresh);
        if (*liw < need_i) { info[0] = -3; info[1] = need_i; } else { info[0] = -4; info[1] = need_r; }
        return;
    }
    char *real1 = calloc(b + 1, 1); /* which slots are real: a block whose slot 1 holds no node is padded with 1 */
    double *rowmax = calloc(2 * b + 1, sizeof(double)); /* by slot */
    if (!real1 || !rowmax) {
        free(real1); free(rowmax); free(fresh);
        info[0] = OUT_OF_MEMORY;
        return;
    }
    if (fresh) {
        memcpy(code, fresh, n * sizeof(fint));
        free(fresh);
        __atomic_add_fetch(&repairs, 1, __ATOMIC_RELAXED);
        have = 0; /* the structure below is built again from these pairs */
    } else if (!have) {
        memcpy(code, ikeep, n * sizeof(fint));
    }
    fint *lp = code + n, *li = lp + b + 1, *parent = li + lnz, *lnzc = parent + b,
         *flag = lnzc + b, *pattern = flag + b, *cp = pattern + b, *ci = cp + b + 1, *cs = ci + nz, *pos = cs + nz;
    double *dinv = a + nz, *lx = dinv + 4 * b, *y = lx + 4 * lnz, *cx = y + 4 * b;
    if (have) {
        /* the structure of these pairs is in iw already (an earlier factorization of the same solve) */
        for (int t = 0; t < nz; t++) cx[pos[t]] = a[t];
    } else {
        hdr[0] = 0;
        block_columns(nz, b, irn, icn, a, code, cp, ci, cs, cx, pos, flag); /* flag: free until the symbolic */
        block_symbolic(b, cp, ci, lp, parent, lnzc, flag);
        hdr[1] = n; hdr[2] = b; hdr[3] = lnz; hdr[4] = nz; hdr[5] = stamp; hdr[0] = MAGIC;
    }
    for (int i = 0; i < n; i++) if (code[i] & 1) real1[code[i] >> 1] = 1;
    for (int t = 0; t < nz; t++) {
        double v = fabs(a[t]);
        int s = code[irn[t] - 1], r = code[icn[t] - 1];
        if (v > rowmax[s]) rowmax[s] = v;
        if (v > rowmax[r]) rowmax[r] = v;
    }
    int negative = 0, perturbed = 0;
    memset(y, 0, 4 * b * sizeof(double));
    for (int k = 0; k < b; k++) {
        int top = b;
        flag[k] = k;
        lnzc[k] = 0;
        for (int p = cp[k]; p < cp[k + 1]; p++) {
            int i = ci[p];
            double *yi = y + 4 * i, v = cx[p];
            if (cs[p] == 4) { yi[1] += v; yi[2] += v; } else yi[cs[p]] += v;
            int len = 0;
            for (; flag[i] != k; i = parent[i]) { pattern[len++] = i; flag[i] = k; }
            while (len > 0) pattern[--top] = pattern[--len];
        }
        double dk[4];
        memcpy(dk, y + 4 * k, sizeof dk);
        memset(y + 4 * k, 0, 4 * sizeof(double));
        if (!real1[k]) dk[3] += 1.0;
        for (; top < b; top++) {
            int i = pattern[top];
            double yi[4], t[4], lki[4];
            memcpy(yi, y + 4 * i, sizeof yi);
            memset(y + 4 * i, 0, 4 * sizeof(double));
            int p2 = lp[i] + lnzc[i], p;
            for (p = lp[i]; p < p2; p++) {
                mul(lx + 4 * p, yi, t);
                double *yr = y + 4 * li[p];
                yr[0] -= t[0]; yr[1] -= t[1]; yr[2] -= t[2]; yr[3] -= t[3];
            }
            mul_tn(yi, dinv + 4 * i, lki);
            mul(lki, yi, t);
            dk[0] -= t[0]; dk[1] -= t[1]; dk[2] -= t[2]; dk[3] -= t[3];
            li[p] = k;
            memcpy(lx + 4 * p, lki, sizeof lki);
            lnzc[i]++;
        }
        double off = 0.5 * (dk[1] + dk[2]);
        double d0 = dk[0], d3 = dk[3];
        double det = d0 * d3 - off * off;
        int singular;
        if (!real1[k]) {
            singular = !(fabs(d0) > 1e-14 * strictness * rowmax[2 * k]);
        } else {
            double term = fmax(fabs(d0 * d3), off * off);
            singular = !(fabs(det) > 1e-12 * strictness * term) || !(term > 1e-28 * rowmax[2 * k] * rowmax[2 * k + 1]);
        }
        if (singular) {
            perturbed++;
            double t0 = 1e-10 * (rowmax[2 * k] > 0 ? rowmax[2 * k] : 1.0);
            double t1 = 1e-10 * (rowmax[2 * k + 1] > 0 ? rowmax[2 * k + 1] : 1.0);
            /* a primal slot gets +t, a multiplier slot -t: the inertia IPOPT asks for */
            d0 += d0 < 0 ? -t0 : t0;
            if (real1[k]) d3 -= t1;
            det = d0 * d3 - off * off;
        }
        double *di = dinv + 4 * k;
        di[0] = d3 / det; di[1] = -off / det; di[2] = -off / det; di[3] = d0 / det;
        int neg = det < 0 ? 1 : (d0 + d3 < 0 ? 2 : 0);
        negative += neg;
    }
    free(real1); free(rowmax);
    *maxfrt = 2 * b;
    info[14] = negative;
    {
        static int dumped = 0;
        const char *dir = getenv("BLOCK_LDL_DUMPDIR");
        int index = dir ? __atomic_fetch_add(&dumped, 1, __ATOMIC_RELAXED) : 0;
        if (dir && index < 400) {
            char name[512];
            snprintf(name, sizeof name, "%s/f%04d.txt", dir, index);
            FILE *f = fopen(name, "w");
            if (!f) {
                if (index == 0) fprintf(stderr, "block_ldl: cannot write %s (BLOCK_LDL_DUMPDIR): no matrices dumped\n", name);
            } else {
                fprintf(f, "%d %d %d %d\n", n, nz, negative, perturbed);
                for (int i = 0; i < n; i++) fprintf(f, "%d\n", code[i]);
                for (int t = 0; t < nz; t++) fprintf(f, "%d %d %.17g\n", irn[t], icn[t], a[t]);
                fclose(f);
            }
        }
    }
    info[1] = n - perturbed;
    if (perturbed && !getenv("BLOCK_LDL_QUIET_PERTURB")) info[0] = 3; /* rank deficient, as MA27 says it: IPOPT regularises and factorizes again */
    if (verbose() && perturbed) fprintf(stderr, "block_ldl: %d perturbed pivots\n", perturbed);
}

/* ---------------------------------------------------------------- solve */
static void ma27cd_impl(const fint *N, const double *a, const fint *la, const fint *iw, const fint *liw, double *w,
                        const fint *maxfrt, double *rhs, const fint *iw1, const fint *nsteps, const fint *icntl,
                        fint *info) {
    (void)la; (void)liw; (void)maxfrt; (void)iw1; (void)nsteps; (void)icntl; (void)info;
    int n = *N, b = iw[2], lnz = iw[3], nz = iw[4];
    const fint *code = iw + HEADER, *lp = code + n, *li = lp + b + 1;
    const double *dinv = a + nz, *lx = dinv + 4 * b;
    (void)lnz;
    memset(w, 0, 2 * b * sizeof(double));
    for (int i = 0; i < n; i++) w[code[i]] = rhs[i];
    for (int j = 0; j < b; j++) {
        double z0 = w[2 * j], z1 = w[2 * j + 1];
        for (int p = lp[j]; p < lp[j + 1]; p++) {
            const double *l = lx + 4 * p;
            double *zr = w + 2 * li[p];
            zr[0] -= l[0] * z0 + l[1] * z1;
            zr[1] -= l[2] * z0 + l[3] * z1;
        }
    }
    for (int j = 0; j < b; j++) {
        const double *d = dinv + 4 * j;
        double z0 = w[2 * j], z1 = w[2 * j + 1];
        w[2 * j] = d[0] * z0 + d[1] * z1;
        w[2 * j + 1] = d[2] * z0 + d[3] * z1;
    }
    for (int j = b - 1; j >= 0; j--) {
        double z0 = w[2 * j], z1 = w[2 * j + 1];
        for (int p = lp[j]; p < lp[j + 1]; p++) {
            const double *l = lx + 4 * p;
            const double *zr = w + 2 * li[p];
            z0 -= l[0] * zr[0] + l[2] * zr[1];
            z1 -= l[1] * zr[0] + l[3] * zr[1];
        }
        w[2 * j] = z0; w[2 * j + 1] = z1;
    }
    for (int i = 0; i < n; i++) rhs[i] = w[code[i]];
}

#define TIMED(f, acc, cnt) \
    if (!timing()) { f; } else { \
        double s_ = now(); f; double d_ = now() - s_; \
        pthread_mutex_lock(&timing_lock); acc += d_; cnt++; pthread_mutex_unlock(&timing_lock); \
    }
#define ma27ad_timed(...) do { TIMED(ma27ad_impl(__VA_ARGS__), t_a, n_a) } while (0)
#define ma27bd_timed(...) do { TIMED(ma27bd_impl(__VA_ARGS__), t_b, n_b) } while (0)
#define ma27cd_timed(...) do { TIMED(ma27cd_impl(__VA_ARGS__), t_c, n_c) } while (0)
#define EXPORT(name, impl, params, args) \
    void name params { impl args; } \
    void name##_ params { impl args; }

EXPORT(ma27id, ma27id_impl, (fint *icntl, double *cntl), (icntl, cntl))
EXPORT(ma27ad, ma27ad_timed,
       (const fint *N, const fint *NZ, const fint *irn, const fint *icn, fint *iw, const fint *liw, fint *ikeep,
        fint *iw1, fint *nsteps, const fint *iflag, fint *icntl, const double *cntl, fint *info, double *ops),
       (N, NZ, irn, icn, iw, liw, ikeep, iw1, nsteps, iflag, icntl, cntl, info, ops))
EXPORT(ma27bd, ma27bd_timed,
       (const fint *N, const fint *NZ, const fint *irn, const fint *icn, double *a, const fint *la, fint *iw,
        const fint *liw, const fint *ikeep, const fint *nsteps, fint *maxfrt, fint *iw1, const fint *icntl,
        const double *cntl, fint *info),
       (N, NZ, irn, icn, a, la, iw, liw, ikeep, nsteps, maxfrt, iw1, icntl, cntl, info))
EXPORT(ma27cd, ma27cd_timed,
       (const fint *N, const double *a, const fint *la, const fint *iw, const fint *liw, double *w,
        const fint *maxfrt, double *rhs, const fint *iw1, const fint *nsteps, const fint *icntl, fint *info),
       (N, a, la, iw, liw, w, maxfrt, rhs, iw1, nsteps, icntl, info))
