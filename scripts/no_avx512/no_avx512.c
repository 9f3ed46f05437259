/*
 * no_avx512.so: make this process (and every process it starts) see a CPU without AVX-512.
 *
 * Why: Clarabel's linear algebra (faer) picks its SIMD kernels from CPUID at run time and no
 * environment variable changes that, so a machine with AVX-512 cannot otherwise run the
 * solver's AVX2 path, which is the one users without AVX-512 get.
 *
 * How: Linux's CPUID faulting (arch_prctl(ARCH_SET_CPUID, 0); the CPU flag `cpuid_fault`)
 * makes every CPUID instruction raise SIGSEGV. The handler below runs the real CPUID with
 * faulting briefly off, clears the AVX-512 feature bits (leaf 7) and the AVX-512 state
 * components (leaf 0xD), writes the result into the interrupted registers and steps over the
 * 2-byte instruction. Everything else runs natively, at full speed. Faulting is per thread,
 * inherited by threads and fork, and reset by execve, so LD_PRELOAD carries it to child
 * processes through the environment.
 *
 * Programs that install their own SIGSEGV handler (gcc's cc1, Python's faulthandler, which
 * pytest enables) keep working: sigaction() and signal() for SIGSEGV are interposed, so the
 * program's handler is remembered rather than installed, and every SIGSEGV that is not a
 * faulted CPUID goes to it (or kills the process when it is the default action).
 *
 * Limits: glibc and the dynamic loader read CPUID before any preloaded constructor runs; hold
 * glibc back with GLIBC_TUNABLES (see run.sh). Statically linked programs and processes started
 * without the environment are not covered. If the kernel or CPU lacks CPUID faulting, the
 * constructor says so on stderr and exits with status 3, so a run never silently keeps AVX-512.
 *
 * Build: cc -O2 -shared -fPIC -o no_avx512.so no_avx512.c -ldl
 */
#define _GNU_SOURCE
#include <asm/prctl.h>
#include <dlfcn.h>
#include <cpuid.h>
#include <signal.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/syscall.h>
#include <ucontext.h>
#include <unistd.h>

static int set_cpuid_faulting(int on) {
    return (int)syscall(SYS_arch_prctl, ARCH_SET_CPUID, on ? 0 : 1);
}

/* Leaf 7 sub-leaf 0 feature bits that a Haswell-class (x86-64-v3) CPU does not have. */
static const uint32_t LEAF7_EBX_AVX512 = (1u << 16)   /* AVX512F */
                                        | (1u << 17)  /* AVX512DQ */
                                        | (1u << 21)  /* AVX512_IFMA */
                                        | (1u << 26)  /* AVX512PF */
                                        | (1u << 27)  /* AVX512ER */
                                        | (1u << 28)  /* AVX512CD */
                                        | (1u << 30)  /* AVX512BW */
                                        | (1u << 31); /* AVX512VL */
static const uint32_t LEAF7_ECX_AVX512 = (1u << 1)    /* AVX512_VBMI */
                                        | (1u << 6)   /* AVX512_VBMI2 */
                                        | (1u << 11)  /* AVX512_VNNI */
                                        | (1u << 12)  /* AVX512_BITALG */
                                        | (1u << 14); /* AVX512_VPOPCNTDQ */
static const uint32_t LEAF7_EDX_AVX512 = (1u << 2)    /* AVX512_4VNNIW */
                                        | (1u << 3)   /* AVX512_4FMAPS */
                                        | (1u << 8)   /* AVX512_VP2INTERSECT */
                                        | (1u << 23); /* AVX512_FP16 */
static const uint32_t LEAF7_1_EAX_AVX512 = (1u << 5); /* AVX512_BF16 */
static const uint32_t XSAVE_AVX512_STATE = 0xE0u;     /* opmask, ZMM_Hi256, Hi16_ZMM */

typedef int (*sigaction_fn)(int, const struct sigaction *, struct sigaction *);
static sigaction_fn real_sigaction;
/* The program's own SIGSEGV disposition: what it asked for, not installed. */
static struct sigaction program_action;

static sigaction_fn find_real_sigaction(void) {
    if (!real_sigaction) real_sigaction = (sigaction_fn)dlsym(RTLD_NEXT, "sigaction");
    return real_sigaction;
}

static void pass_to_program(int sig, siginfo_t *info, void *context) {
    struct sigaction action = program_action;
    if (action.sa_handler == SIG_DFL || action.sa_handler == SIG_IGN) {
        /* Default action: uninstall ourselves; the faulting instruction re-runs and kills. */
        struct sigaction dfl;
        memset(&dfl, 0, sizeof dfl);
        dfl.sa_handler = SIG_DFL;
        find_real_sigaction()(sig, &dfl, NULL);
        return;
    }
    if (action.sa_flags & SA_RESETHAND) {
        memset(&program_action, 0, sizeof program_action);
        program_action.sa_handler = SIG_DFL;
    }
    if (action.sa_flags & SA_SIGINFO)
        action.sa_sigaction(sig, info, context);
    else
        action.sa_handler(sig);
}

static void on_sigsegv(int sig, siginfo_t *info, void *context) {
    ucontext_t *uc = (ucontext_t *)context;
    greg_t *reg = uc->uc_mcontext.gregs;
    /* A faulted CPUID is a general-protection fault (SI_KERNEL) at the bytes 0F A2; only then
     * is it safe and right to read the instruction. */
    const unsigned char *ip = (const unsigned char *)reg[REG_RIP];
    if (info->si_code != SI_KERNEL || ip[0] != 0x0F || ip[1] != 0xA2) {
        pass_to_program(sig, info, context);
        return;
    }
    uint32_t leaf = (uint32_t)reg[REG_RAX], subleaf = (uint32_t)reg[REG_RCX];
    uint32_t a, b, c, d;
    set_cpuid_faulting(0);
    __cpuid_count(leaf, subleaf, a, b, c, d);
    set_cpuid_faulting(1);
    if (leaf == 7 && subleaf == 0) {
        b &= ~LEAF7_EBX_AVX512;
        c &= ~LEAF7_ECX_AVX512;
        d &= ~LEAF7_EDX_AVX512;
    } else if (leaf == 7 && subleaf == 1) {
        a &= ~LEAF7_1_EAX_AVX512;
    } else if (leaf == 0xD && subleaf == 0) {
        a &= ~XSAVE_AVX512_STATE;
    }
    reg[REG_RAX] = a;
    reg[REG_RBX] = b;
    reg[REG_RCX] = c;
    reg[REG_RDX] = d;
    reg[REG_RIP] += 2;
}

int sigaction(int sig, const struct sigaction *action, struct sigaction *old) {
    if (sig != SIGSEGV) return find_real_sigaction()(sig, action, old);
    if (old) *old = program_action;
    if (action) program_action = *action;
    return 0;
}

sighandler_t signal(int sig, sighandler_t handler) {
    if (sig != SIGSEGV) {
        struct sigaction action, old;
        memset(&action, 0, sizeof action);
        action.sa_handler = handler;
        action.sa_flags = SA_RESTART;
        sigemptyset(&action.sa_mask);
        if (find_real_sigaction()(sig, &action, &old) != 0) return SIG_ERR;
        return old.sa_handler;
    }
    sighandler_t previous = program_action.sa_handler;
    memset(&program_action, 0, sizeof program_action);
    program_action.sa_handler = handler;
    program_action.sa_flags = SA_RESTART;
    return previous;
}

__attribute__((constructor)) static void install(void) {
    struct sigaction action;
    memset(&action, 0, sizeof action);
    action.sa_sigaction = on_sigsegv;
    action.sa_flags = SA_SIGINFO | SA_NODEFER;
    sigemptyset(&action.sa_mask);
    program_action.sa_handler = SIG_DFL;
    if (!find_real_sigaction() || find_real_sigaction()(SIGSEGV, &action, NULL) != 0 ||
        set_cpuid_faulting(1) != 0) {
        fprintf(stderr, "no_avx512.so: CPUID faulting is not available here (needs Linux >= 4.12 "
                        "and the CPU flag cpuid_fault); refusing to run with AVX-512 visible\n");
        _exit(3);
    }
}
