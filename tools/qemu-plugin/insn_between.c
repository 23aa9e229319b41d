/*
 * QEMU TCG plugin: counts the guest instructions executed between marker functions. Every
 * call of a "begin" marker opens an interval under that marker's label, every call of the
 * "end" marker closes the innermost open one (intervals nest), and each closed interval is
 * appended as a line "label count" to a file. Instructions inside the marker functions'
 * bodies are not counted; the call instructions at the call sites are (the firmware counts an
 * empty interval so the host can subtract them).
 *
 *   qemu-system-arm ... -plugin tools/qemu-plugin/insn_between.so,begin=core_step:0x8001234:18,end=0x8001240:20,out=counts.txt
 *
 * With pcs=FILE it also counts the instructions of each interval by program counter and keeps
 * FILE as lines "label 0xADDRESS count" (the innermost open interval's label), rewritten
 * whenever an outermost interval closes: a profile to map to source lines with addr2line.
 *
 * begin=LABEL:ADDRESS:SIZE (repeatable) and end=ADDRESS:SIZE are the markers' ELF symbols
 * (the Thumb bit of the address is ignored). Interrupts taken inside an interval would be
 * counted too: the firmware masks them while an interval is open.
 *
 * Debian's QEMU accepts plugins built for API v2 to v4 but ships no header, so the few types
 * and functions used here are declared below (their signatures are unchanged since API v1).
 */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define EXPORT __attribute__((visibility("default")))

typedef uint64_t qemu_plugin_id_t;
struct qemu_plugin_tb;
struct qemu_plugin_insn;
typedef struct qemu_info_t qemu_info_t; /* only passed through */
enum qemu_plugin_cb_flags { QEMU_PLUGIN_CB_NO_REGS, QEMU_PLUGIN_CB_R_REGS, QEMU_PLUGIN_CB_RW_REGS };
typedef void (*qemu_plugin_vcpu_udata_cb_t)(unsigned int vcpu_index, void *userdata);
typedef void (*qemu_plugin_vcpu_tb_trans_cb_t)(qemu_plugin_id_t id, struct qemu_plugin_tb *tb);
typedef void (*qemu_plugin_udata_cb_t)(qemu_plugin_id_t id, void *userdata);

void qemu_plugin_register_vcpu_tb_trans_cb(qemu_plugin_id_t id, qemu_plugin_vcpu_tb_trans_cb_t cb);
void qemu_plugin_register_vcpu_insn_exec_cb(struct qemu_plugin_insn *insn, qemu_plugin_vcpu_udata_cb_t cb,
                                            enum qemu_plugin_cb_flags flags, void *userdata);
void qemu_plugin_register_atexit_cb(qemu_plugin_id_t id, qemu_plugin_udata_cb_t cb, void *userdata);
size_t qemu_plugin_tb_n_insns(const struct qemu_plugin_tb *tb);
struct qemu_plugin_insn *qemu_plugin_tb_get_insn(const struct qemu_plugin_tb *tb, size_t idx);
uint64_t qemu_plugin_insn_vaddr(const struct qemu_plugin_insn *insn);

/* The oldest API level whose functions are used here; QEMU 10 accepts 2..4. */
EXPORT int qemu_plugin_version = 2;

#define MAX_MARKERS 32
#define MAX_DEPTH 16

struct marker {
    char label[48];
    uint64_t start, size;
};

static struct marker begins[MAX_MARKERS];
static int n_begins;
static struct marker end_marker;
static FILE *out;
/* One emulated Cortex-M4: one vCPU, so plain counters suffice. */
static uint64_t total;
static struct { int label; uint64_t at; } open_intervals[MAX_DEPTH];
static int depth;

/* The per-address profile (pcs=FILE): one slot per instruction address, allocated when first
 * translated, counting by the innermost open interval's label. */
struct pc_slot {
    uint64_t pc;
    uint64_t counts[MAX_MARKERS];
};
#define MAX_SLOTS (1 << 17) /* a power of two: open addressing by the address's bits */
static struct pc_slot *slots[MAX_SLOTS];
static const char *pcs_path;

static struct pc_slot *slot_for(uint64_t pc)
{
    for (uint64_t probe = 0; probe < MAX_SLOTS; probe++) {
        struct pc_slot **s = &slots[((pc >> 1) + probe) & (MAX_SLOTS - 1)];
        if (*s == NULL) {
            *s = calloc(1, sizeof **s);
            if (*s != NULL) {
                (*s)->pc = pc;
            }
            return *s;
        }
        if ((*s)->pc == pc) {
            return *s;
        }
    }
    return NULL;
}

static void write_pcs(void)
{
    FILE *f = fopen(pcs_path, "w");
    if (f == NULL) {
        return;
    }
    for (int i = 0; i < MAX_SLOTS; i++) {
        for (int k = 0; slots[i] != NULL && k < n_begins; k++) {
            if (slots[i]->counts[k] != 0) {
                fprintf(f, "%s %#llx %llu\n", begins[k].label, (unsigned long long)slots[i]->pc,
                        (unsigned long long)slots[i]->counts[k]);
            }
        }
    }
    fclose(f);
}

static void on_insn_profiled(unsigned int vcpu, void *udata)
{
    (void)vcpu;
    total++;
    struct pc_slot *s = udata;
    if (s != NULL && depth > 0 && depth <= MAX_DEPTH) {
        s->counts[open_intervals[depth - 1].label]++;
    }
}

static void on_insn(unsigned int vcpu, void *udata)
{
    (void)vcpu;
    (void)udata;
    total++;
}

static void on_begin(unsigned int vcpu, void *udata)
{
    (void)vcpu;
    if (depth < MAX_DEPTH) {
        open_intervals[depth].label = (int)(intptr_t)udata;
        open_intervals[depth].at = total;
    }
    depth++;
}

static void on_end(unsigned int vcpu, void *udata)
{
    (void)vcpu;
    (void)udata;
    if (depth == 0) {
        return; /* an end without a begin: nothing to report */
    }
    depth--;
    if (depth < MAX_DEPTH) {
        fprintf(out, "%s %llu\n", begins[open_intervals[depth].label].label,
                (unsigned long long)(total - open_intervals[depth].at));
        /* The host kills QEMU when it has what it needs: every line must be on disk by then. */
        fflush(out);
    }
    if (pcs_path != NULL && depth == 0) {
        write_pcs();
    }
}

static int inside(const struct marker *m, uint64_t pc)
{
    return pc >= m->start && pc < m->start + m->size;
}

static void on_translate(qemu_plugin_id_t id, struct qemu_plugin_tb *tb)
{
    (void)id;
    size_t n = qemu_plugin_tb_n_insns(tb);
    for (size_t i = 0; i < n; i++) {
        struct qemu_plugin_insn *insn = qemu_plugin_tb_get_insn(tb, i);
        uint64_t pc = qemu_plugin_insn_vaddr(insn);
        qemu_plugin_vcpu_udata_cb_t cb = on_insn;
        void *udata = NULL;
        if (pcs_path != NULL) {
            cb = on_insn_profiled;
            udata = slot_for(pc);
        }
        if (inside(&end_marker, pc)) {
            cb = pc == end_marker.start ? on_end : NULL;
        }
        for (int k = 0; k < n_begins; k++) {
            if (inside(&begins[k], pc)) {
                cb = pc == begins[k].start ? on_begin : NULL;
                udata = (void *)(intptr_t)k;
            }
        }
        if (cb != NULL) {
            qemu_plugin_register_vcpu_insn_exec_cb(insn, cb, QEMU_PLUGIN_CB_NO_REGS, udata);
        }
    }
}

static void on_plugin_exit(qemu_plugin_id_t id, void *udata)
{
    (void)id;
    (void)udata;
    if (out != NULL && out != stderr) {
        fclose(out);
    }
}

/* "ADDRESS:SIZE" into m; 0 on success. */
static int parse_range(const char *text, struct marker *m)
{
    char *rest;
    m->start = strtoull(text, &rest, 0) & ~1ULL;
    if (*rest != ':') {
        return 1;
    }
    m->size = strtoull(rest + 1, &rest, 0);
    return *rest != '\0' || m->start == 0 || m->size == 0;
}

EXPORT int qemu_plugin_install(qemu_plugin_id_t id, const qemu_info_t *info, int argc, char **argv)
{
    (void)info;
    const char *path = NULL;
    for (int i = 0; i < argc; i++) {
        const char *a = argv[i];
        if (strncmp(a, "begin=", 6) == 0 && n_begins < MAX_MARKERS) {
            const char *colon = strchr(a + 6, ':');
            struct marker *m = &begins[n_begins];
            size_t len = colon != NULL ? (size_t)(colon - (a + 6)) : 0;
            if (len == 0 || len >= sizeof m->label || parse_range(colon + 1, m)) {
                fprintf(stderr, "insn_between: bad %s (begin=LABEL:ADDRESS:SIZE)\n", a);
                return 1;
            }
            memcpy(m->label, a + 6, len);
            m->label[len] = '\0';
            n_begins++;
        } else if (strncmp(a, "end=", 4) == 0) {
            if (parse_range(a + 4, &end_marker)) {
                fprintf(stderr, "insn_between: bad %s (end=ADDRESS:SIZE)\n", a);
                return 1;
            }
        } else if (strncmp(a, "out=", 4) == 0) {
            path = a + 4;
        } else if (strncmp(a, "pcs=", 4) == 0) {
            pcs_path = a + 4;
        } else {
            fprintf(stderr, "insn_between: unknown argument %s (begin=, end=, out=, pcs=)\n", a);
            return 1;
        }
    }
    if (n_begins == 0 || end_marker.start == 0) {
        fprintf(stderr, "insn_between: needs begin=LABEL:ADDRESS:SIZE (one or more) and end=ADDRESS:SIZE\n");
        return 1;
    }
    out = path != NULL ? fopen(path, "w") : stderr;
    if (out == NULL) {
        fprintf(stderr, "insn_between: cannot open %s\n", path);
        return 1;
    }
    qemu_plugin_register_vcpu_tb_trans_cb(id, on_translate);
    qemu_plugin_register_atexit_cb(id, on_plugin_exit, NULL);
    return 0;
}
