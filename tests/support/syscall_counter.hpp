// Counts the system calls one thread makes, by a seccomp filter on that thread alone: every
// system call except the few `allowed` ones traps (SIGSYS), the handler counts it and makes it
// fail with ENOSYS. The proofs of the real-time path use it to show that a stretch of code makes
// no system call at all (the vDSO clock reads never reach the kernel, so they are not counted).
//
// A seccomp filter cannot be removed: install it only on a thread that does the measured work
// and then ends (the filter dies with the thread). Needs root (CAP_SYS_ADMIN) or sets
// no_new_privs for that thread.
#pragma once

#include <linux/audit.h>
#include <linux/filter.h>
#include <linux/seccomp.h>
#include <signal.h>
#include <stddef.h>
#include <sys/prctl.h>
#include <sys/syscall.h>
#include <ucontext.h>

#include <atomic>
#include <cerrno>
#include <cstdint>
#include <initializer_list>
#include <vector>

namespace ds1928::test {

class SyscallCounter {
 public:
  // Process-wide: the SIGSYS handler (installed once).
  static void install_handler() {
    struct sigaction sa {};
    sa.sa_sigaction = &on_sigsys;
    sa.sa_flags = SA_SIGINFO;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGSYS, &sa, nullptr);
  }

  // Calling thread only: from now on every system call but `allowed` (and the few the handler
  // itself and the thread's exit need) is counted and fails. Returns false when the kernel
  // refused the filter.
  [[nodiscard]] static bool trap_all_but(std::initializer_list<long> allowed) {
    install_handler();
    std::vector<long> ok(allowed);
    ok.push_back(SYS_rt_sigreturn);
    ok.push_back(SYS_exit);
    ok.push_back(SYS_exit_group);
    ok.push_back(SYS_munmap);  // thread exit frees its stack cache
    ok.push_back(SYS_madvise);
    ok.push_back(SYS_rt_sigprocmask);  // thread exit blocks signals
    std::vector<sock_filter> prog;
    prog.push_back(BPF_STMT(BPF_LD | BPF_W | BPF_ABS, offsetof(seccomp_data, arch)));
    prog.push_back(BPF_JUMP(BPF_JMP | BPF_JEQ | BPF_K, AUDIT_ARCH_X86_64, 1, 0));
    prog.push_back(BPF_STMT(BPF_RET | BPF_K, SECCOMP_RET_ALLOW));  // not x86-64: no filter
    prog.push_back(BPF_STMT(BPF_LD | BPF_W | BPF_ABS, offsetof(seccomp_data, nr)));
    for (long nr : ok) {
      prog.push_back(BPF_JUMP(BPF_JMP | BPF_JEQ | BPF_K, static_cast<uint32_t>(nr), 0, 1));
      prog.push_back(BPF_STMT(BPF_RET | BPF_K, SECCOMP_RET_ALLOW));
    }
    prog.push_back(BPF_STMT(BPF_RET | BPF_K, SECCOMP_RET_TRAP));
    sock_fprog fprog{static_cast<unsigned short>(prog.size()), prog.data()};
    (void)prctl(PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0);
    return syscall(SYS_seccomp, SECCOMP_SET_MODE_FILTER, 0, &fprog) == 0;
  }

  // System calls trapped so far, on every thread that installed the filter, and the number of
  // the last one.
  [[nodiscard]] static uint64_t trapped() noexcept { return trapped_.load(); }
  [[nodiscard]] static long last_nr() noexcept { return last_nr_.load(); }

 private:
  static void on_sigsys(int, siginfo_t* info, void* context) {
    trapped_.fetch_add(1);
    last_nr_.store(info->si_syscall);
#if defined(__x86_64__)
    static_cast<ucontext_t*>(context)->uc_mcontext.gregs[REG_RAX] = -ENOSYS;
#else
    (void)context;
#endif
  }
  static inline std::atomic<uint64_t> trapped_{0};
  static inline std::atomic<long> last_nr_{0};
};

}  // namespace ds1928::test
