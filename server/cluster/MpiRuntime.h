#pragma once
// The MPI library's lifetime in a process: MPI_Init_thread on construction,
// MPI_Finalize on destruction. One per process, made by the program's main path; the
// libraries never initialise MPI themselves.
#include <mpi.h>

namespace bc::server::cluster {

class MpiRuntime {
  public:
    /// Initialises MPI asking for `required` thread support (MPI_THREAD_SERIALIZED: MPI is
    /// called from one thread at a time, not necessarily the main one). @throw ClusterError
    /// when MPI is already initialised or the library offers less than `required`.
    explicit MpiRuntime(int required = MPI_THREAD_SERIALIZED);
    ~MpiRuntime();
    MpiRuntime(const MpiRuntime&) = delete;
    MpiRuntime& operator=(const MpiRuntime&) = delete;

    int rank() const { return mRank; }
    int size() const { return mSize; }

    /// Ends every rank of MPI_COMM_WORLD with `code` (what a rank does on an error the
    /// others cannot know of: they would wait for it for ever). Does not return.
    [[noreturn]] static void abortAll(int code);

  private:
    int mRank = 0, mSize = 1;
};

} // namespace bc::server::cluster
